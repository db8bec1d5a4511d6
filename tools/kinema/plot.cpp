#include "plot.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <fstream>

#include "kinema/error.hpp"

extern char** environ;

namespace kinema::cli {

// Single quotes: gnuplot expands neither backquotes nor escapes inside them; a quote
// inside is written twice.
std::string gnuplot_quote(const std::string& text) {
  std::string out = "'";
  for (char c : text) {
    out += c;
    if (c == '\'') out += '\'';
  }
  return out + "'";
}

namespace {

// Runs gnuplot on `script` without a shell, its stderr into `log`. True on success.
bool run_gnuplot(const std::string& script, const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::string program = "gnuplot";
  char* argv[] = {program.data(), const_cast<char*>(script.c_str()), nullptr};
  pid_t pid = 0;
  const int spawned = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return false;
  int status = 0;
  if (waitpid(pid, &status, 0) < 0) return false;
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

}  // namespace

void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script) {
  const std::filesystem::path gp = dir / (name + ".gp");
  {
    std::ofstream out(gp);
    out << "set terminal svg size 900,600 dynamic noenhanced font 'sans,13' background rgb 'white'\n"
        << "set output " << gnuplot_quote((dir / (name + ".svg")).string()) << "\n"
        << script << "\n"
        << "set terminal pngcairo size 900,600 noenhanced font 'sans,11'\n"
        << "set output " << gnuplot_quote((dir / (name + ".png")).string()) << "\n"
        << "replot\n";
    if (!out) throw Error(gp.string() + ": cannot write the chart script");
  }
  if (!run_gnuplot(gp.string(), (dir / (name + ".log")).string())) {
    throw Error("gnuplot failed on " + gp.string() + " (is gnuplot-nox installed? see " +
                (dir / (name + ".log")).string() + ")");
  }
  std::filesystem::remove(dir / (name + ".log"));
}

}  // namespace kinema::cli
