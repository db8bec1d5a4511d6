// Fuzz target: the input is an argument list, arguments separated by NUL bytes. The
// command line is parsed and checked, never run (stress's options are also checked as before
// a run, and a small scene's bodies built). A usage error (CLI::ParseError) or
// kinema::Error is a clean refusal; anything else escaping is a finding.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "command_line.hpp"
#include "stress_command.hpp"
#include "kinema/error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  constexpr std::size_t kMaxArgs = 16;
  std::vector<std::string> args{"kinema"};
  std::string arg;
  for (std::size_t i = 0; i < size && args.size() < kMaxArgs + 1; ++i) {
    if (data[i] == 0) {
      args.push_back(std::move(arg));
      arg.clear();
    } else {
      arg += char(data[i]);
    }
  }
  if (size > 0 && data[size - 1] != 0 && args.size() < kMaxArgs + 1) args.push_back(arg);
  std::vector<const char*> argv;
  for (const std::string& a : args) argv.push_back(a.c_str());
  argv.push_back(nullptr);

  kinema::cli::CommandLine line;
  const auto app = kinema::cli::make_app(line);
  try {
    kinema::cli::parse_command_line(*app, line, int(args.size()), argv.data());
    // stress: its checks before work, and for small scenes its bodies and steppers.
    if (line.command == "stress") kinema::cli::check_stress(line.stress, 4096);
  } catch (const CLI::ParseError&) {
  } catch (const kinema::Error&) {
  }
  return 0;
}
