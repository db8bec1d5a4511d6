#include "plot.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "interrupt.hpp"
#include "kinema/error.hpp"

extern char** environ;

namespace kinema::cli {

OutputFile::OutputFile(const std::filesystem::path& path) : std::ofstream(path), path_(path) {
  precision(17);
  if (!*this) throw Error(printable(path.string()) + ": cannot write: " + std::strerror(errno));
}

void OutputFile::close() {
  std::ofstream::close();
  if (!*this) throw Error(printable(path_.string()) + ": cannot write (disk full?)");
}

// Titles longer than this are cut: a chart title is one line.
constexpr std::size_t kMaxTitleBytes = 300;

std::string gnuplot_quote(const std::string& text) {
  std::string out = "'";
  for (char c : printable(text, kMaxTitleBytes)) {
    out += c;
    if (c == '\'') out += '\'';
  }
  return out + "'";
}

namespace {

// Runs gnuplot on the script `name` inside `dir`, without a shell, its stderr into `log`
// (a bare name in `dir` too). Returns the exit status, or -errno when it could not start.
int run_gnuplot(const std::filesystem::path& dir, const std::string& script,
                const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addchdir_np(&actions, dir.c_str());
  posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::string program = "gnuplot", argument = "./" + script;
  char* argv[] = {program.data(), argument.data(), nullptr};
  pid_t pid = 0;
  const int spawned = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return -spawned;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -errno;
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// The last line gnuplot wrote that says what went wrong.
std::string last_complaint(const std::filesystem::path& log) {
  std::ifstream in(log);
  std::string line, last;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t^") != std::string::npos) last = line;
  }
  return printable(last);
}

}  // namespace

void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script) {
  const std::filesystem::path gp = dir / (name + ".gp");
  {
    std::ofstream out(gp);
    out << "set terminal svg size 900,600 dynamic noenhanced font 'sans,13' background rgb 'white'\n"
        << "set output '" << name << ".svg'\n"
        << script << "\n"
        << "set terminal pngcairo size 900,600 noenhanced font 'sans,11'\n"
        << "set output '" << name << ".png'\n"
        << "replot\n";
    out.close();
    if (!out) throw Error(printable(gp.string()) + ": cannot write the chart script");
  }
  const std::string log = name + ".log";
  const int status = run_gnuplot(dir, name + ".gp", log);
  stop_if_interrupted();  // a Ctrl-C reaches gnuplot too: report the signal, not gnuplot
  if (status == -ENOENT) throw Error("gnuplot is not installed (Debian: gnuplot-nox)");
  if (status < 0) {
    throw Error("cannot start gnuplot in " + printable(dir.string()) + ": " + std::strerror(-status));
  }
  if (status != 0) {
    throw Error("gnuplot failed on " + printable(gp.string()) + ": " + last_complaint(dir / log));
  }
  std::filesystem::remove(dir / log);
}

}  // namespace kinema::cli
