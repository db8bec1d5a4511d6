#pragma once
// Running the kinema program from the tests: without a shell (arguments are passed as they
// are, newlines and quotes included), with stdout and stderr captured and the child's exit
// code, signal and peak memory reported.

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace kinema::test {

namespace fs = std::filesystem;

inline fs::path work_dir() {
  static const fs::path dir = [] {
    fs::path d = fs::temp_directory_path() / ("kinema_cli_" + std::to_string(::getpid()));
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

inline std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

inline fs::path write(const std::string& name, const std::string& text) {
  const fs::path p = work_dir() / name;
  std::ofstream(p, std::ios::binary) << text;
  return p;
}

struct Result {
  int code = -1;         // exit code, or 128 + signal when killed
  bool killed = false;   // ended by a signal rather than by exiting
  std::string out, err;
  long peak_kib = 0;     // the child's peak resident memory
};

// Waits (a minute at most) until process `pid` catches `signal`: its handler is installed, so
// the signal tests what the program does with it, not how long the program took to start (an
// unoptimized, sanitized build on a busy machine can take longer than a test's delay).
inline void wait_until_catching(pid_t pid, int signal) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::minutes(1);
  const std::uint64_t bit = std::uint64_t(1) << (signal - 1);
  while (std::chrono::steady_clock::now() < give_up) {
    std::ifstream status("/proc/" + std::to_string(pid) + "/status");
    std::string line;
    while (std::getline(status, line)) {
      if (line.rfind("SigCgt:", 0) == 0 && (std::stoull(line.substr(7), nullptr, 16) & bit) != 0) return;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

// Runs `kinema args...`. `while_running`, when given, is called with the child's pid right
// after it starts (to signal it, for example).
inline Result run_kinema(const std::vector<std::string>& args, const fs::path& stdout_path = {},
                         const std::function<void(pid_t)>& while_running = {}) {
  const fs::path out = stdout_path.empty() ? work_dir() / "stdout.txt" : stdout_path;
  const fs::path err = work_dir() / "stderr.txt";
  std::vector<std::string> words{KINEMA_CLI};
  words.insert(words.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& w : words) argv.push_back(w.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  Result r;
  if (spawned != 0) return r;
  if (while_running) while_running(pid);
  int status = 0;
  rusage usage{};
  pid_t waited;
  while ((waited = ::wait4(pid, &status, 0, &usage)) < 0 && errno == EINTR) {
  }
  if (waited != pid) return r;  // code -1: no exit status
  r.killed = !WIFEXITED(status);
  r.code = r.killed ? 128 + WTERMSIG(status) : WEXITSTATUS(status);
  r.peak_kib = usage.ru_maxrss;
  r.out = stdout_path.empty() ? read(out) : "";
  r.err = read(err);
  return r;
}

inline long lines(const std::string& s) { return std::count(s.begin(), s.end(), '\n'); }

}  // namespace kinema::test
