// The kinema command-line program.
#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "command_line.hpp"
#include "kinema/error.hpp"

int main(int argc, char** argv) {
  kinema::cli::CommandLine line;
  const auto app = kinema::cli::make_app(line);
  try {
    kinema::cli::parse_command_line(*app, line, argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app->exit(e);  // --help
    std::fprintf(stderr, "kinema: error: %s (see kinema --help)\n", kinema::printable(e.what()).c_str());
    return 2;
  }
  try {
    if (line.command == "chart") return kinema::cli::chart_scene(line.chart);
    if (line.command == "stability") return kinema::cli::stability_scene(line.stability);
    return kinema::cli::run_scene(line.run);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kinema: error: %s\n", kinema::printable(e.what()).c_str());
  }
  return 1;
}
