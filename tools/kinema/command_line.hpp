#pragma once
// The command line: subcommands, options and their checks, apart from running them (so
// the parser can be tested and fuzzed alone).

#include <memory>
#include <string>

#include "chart_command.hpp"
#include "run_command.hpp"
#include "stress_command.hpp"

namespace CLI {
class App;
}

namespace kinema::cli {

struct CommandLine {
  std::string command;  // "run", "chart", "stability" or "stress"
  RunOptions run;
  ChartOptions chart;
  StabilityOptions stability;
  StressOptions stress;
  // As typed; parse_command_line sets them in run or stress.
  std::string isa = "auto", precision, guard = "check";
};

// An App that fills `out` when it parses (its options point into `out`).
std::unique_ptr<CLI::App> make_app(CommandLine& out);

// Parses argv into `out`. Throws CLI::ParseError for a usage error or a request for help
// (get_exit_code() 0); kinema::Error never.
void parse_command_line(CLI::App& app, CommandLine& out, int argc, const char* const* argv);

// After parse_command_line threw: where the help for what was typed is, "kinema run --help"
// for an error in `run`, "kinema --help" before any subcommand.
std::string help_command(const CLI::App& app);

}  // namespace kinema::cli
