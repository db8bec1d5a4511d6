// The benchmark program: Google Benchmark's main plus the context a reader needs to trust
// the numbers (CPU model and family, the ISA kinema picks, hardware threads).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <fstream>
#include <string>

#include "kinema/scenes.hpp"

namespace {

std::string cpuinfo_field(const std::string& key) {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(key, 0) == 0) {
      const auto colon = line.find(':');
      return colon == std::string::npos ? "" : line.substr(colon + 2);
    }
  }
  return "unknown";
}

}  // namespace

int main(int argc, char** argv) {
  // For scripts that build a filter for the ISA the kernels will use.
  if (argc == 2 && std::string(argv[1]) == "--print-best-isa") {
    std::printf("%s\n", std::string(kinema::isa_name(kinema::best_isa())).c_str());
    return 0;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("cpu_model", cpuinfo_field("model name"));
  benchmark::AddCustomContext("cpu_family", cpuinfo_field("cpu family"));
  benchmark::AddCustomContext("kinema_best_isa", std::string(kinema::isa_name(kinema::best_isa())));
  benchmark::AddCustomContext("hardware_threads", std::to_string(kinema::hardware_threads()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
