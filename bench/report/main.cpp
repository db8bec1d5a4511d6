// kinema_bench_report BENCH.json [CSV]: turns one kinema_bench run (Google Benchmark JSON,
// ideally with repetitions) into a table of ratios measured in that run: speed-ups over the
// naive and Odeint baselines, the fraction of the compute ceiling and of the streaming
// bandwidth reached, 2-thread scaling, and a verdict on whether 2-thread figures hold.
// Sections whose runs are not in the file are left out.
#include <cstdio>
#include <exception>
#include <memory>
#include <optional>

#include "csv.hpp"
#include "results.hpp"
#include "tables.hpp"

namespace report = kinema::bench::report;

namespace {

std::optional<report::Results> load(const char* path) {
  try {
    return report::load_results(path);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kinema_bench_report: %s: %s\n", path, e.what());
    return std::nullopt;
  }
}

void print_header(const report::Context& c) {
  std::printf("kinema benchmarks on %s (cpu family %s, %d threads), %s; kernels use %s\n", c.cpu_model.c_str(),
              c.cpu_family.c_str(), c.num_cpus, c.date.c_str(), c.isa.c_str());
}

void print_sections(const report::Results& results, report::Rk4Csv* csv) {
  report::Noise noise;
  report::print_rk4_table(results, noise, csv);
  report::print_methods_table(results);
  report::print_bounds_table(results, noise);
  report::print_frame_loop_table(results, noise);
  report::print_isa_table(results);
  report::print_rigid_table(results);
  report::print_game_table(results, noise);
  report::print_paired_scaling(results);
  report::print_coupled_table(results, noise);
  report::print_frame_table(results, noise);
  report::print_guard_table(results, noise);
  report::print_events_table(results, noise);
  report::print_adaptive_table(results, noise);
  report::print_checkpoint_table(results, noise);
  report::print_limits(results);
  noise.print();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: kinema_bench_report BENCH.json [TABLE.csv]\n");
    return 2;
  }
  const auto results = load(argv[1]);
  if (!results) return 1;
  if (results->empty()) {
    std::fprintf(stderr, "kinema_bench_report: %s: no benchmark runs in the file\n", argv[1]);
    return 1;
  }
  print_header(results->context());
  std::unique_ptr<report::Rk4Csv> csv;
  if (argc > 2) csv = std::make_unique<report::Rk4Csv>(argv[2], results->isa());
  if (csv && !csv->ok()) std::fprintf(stderr, "kinema_bench_report: %s: cannot write the CSV; printing the table only\n", argv[2]);
  print_sections(*results, csv && csv->ok() ? csv.get() : nullptr);
  return 0;
}
