// The kinema command-line program. Exit codes: 0 success, 1 an error (bad scene, failed
// write), 2 a usage error, 3 the state stopped being finite, 128 + N stopped by signal N
// (SIGINT 130, SIGTERM 143) at a safe point with every output complete to there.
#include <cerrno>
#include <cstdio>
#include <new>
#include <cstring>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "command_line.hpp"
#include "interrupt.hpp"
#include "kinema/error.hpp"

namespace {

// An error message is one line of bounded length, whatever the input put into it.
constexpr std::size_t kMessageBytes = 1000;

int stopped_by(int signal) {
  std::fprintf(stderr, "kinema: stopped by %s; the outputs written so far are incomplete\n",
               kinema::cli::signal_name(signal).c_str());
  return 128 + signal;
}

int run(const kinema::cli::CommandLine& line) {
  using namespace kinema::cli;
  try {
    if (line.command == "chart") return chart_scene(line.chart);
    if (line.command == "stability") return stability_scene(line.stability);
    if (line.command == "stress") return stress(line.stress);
    return run_scene(line.run);
  } catch (const Interrupted& e) {
    return stopped_by(e.signal);
  } catch (const kinema::Stopped& e) {  // an analysis answering interrupt_request
    if (const int signal = interrupted_by(e)) return stopped_by(signal);
    std::fprintf(stderr, "kinema: error: %s\n", e.what());
  } catch (const std::bad_alloc&) {
    // The scene's checks bound what a run takes; this is what they did not foresee.
    std::fprintf(stderr, "kinema: error: out of memory (the machine's, or ulimit -v); try fewer bodies\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kinema: error: %s\n", kinema::printable(e.what(), kMessageBytes).c_str());
  }
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  kinema::cli::CommandLine line;
  const auto app = kinema::cli::make_app(line);
  try {
    kinema::cli::parse_command_line(*app, line, argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app->exit(e);  // --help, --version
    std::fprintf(stderr, "kinema: error: %s (see %s)\n", kinema::printable(e.what(), kMessageBytes).c_str(),
                 kinema::cli::help_command(*app).c_str());
    return 2;
  }
  kinema::cli::catch_interrupts();
  const int code = run(line);
  // What stdout holds is part of the result: a full disk there is an error, not a success.
  if (std::fflush(stdout) != 0 || std::ferror(stdout) != 0) {
    std::fprintf(stderr, "kinema: error: standard output: cannot write: %s\n", std::strerror(errno));
    return code == 0 ? 1 : code;
  }
  return code;
}
