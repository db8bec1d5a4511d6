// Two threads against one, and the machine's limits with the check on whether the two
// vCPUs were real cores during the run.
#include <cstdio>

#include "machine_limits.hpp"
#include "names.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

constexpr double kRealCores = 1.8;  // pure FMA work scales at least this much on two real cores

void print_paired_header(const std::string& isa) {
  std::printf("\n2 threads against 1, fused RK4, N = 100000, %s, measured in pairs (a few steps on 1 "
              "thread, then on 2; pure FMA work probed before and after each pair)\n", isa.c_str());
}

void print_paired_row(const Results& results, const std::string& p, const std::string& run) {
  std::printf("%-6s %s in the pairs where FMA work scaled 1.8x or more (%s of %s pairs; FMA %s), "
              "%s over all pairs\n",
              p.c_str(), cell(median(results.find(run, "scaling")), "%.2fx").c_str(),
              cell(results.count(run, "pairs_kept"), "%.0f").c_str(), results.value(run, "pairs", "%.0f").c_str(),
              results.value(run, "fma_scaling", "%.2fx").c_str(),
              cell(median(results.find(run, "scaling_all_pairs")), "%.2fx").c_str());
}

void print_scaling_check(const Results& results) {
  const auto one = fma_peak(results, "float", 1);
  const auto two = fma_peak(results, "float", 2);
  if (one && two) {
    const double s = two->median / one->median;
    std::printf("scaling check: pure FMA work runs %.2fx faster on 2 threads: %s\n", s,
                s >= kRealCores ? "two real cores, the 2-thread figures are trustworthy"
                                : "below 1.8x, the vCPUs share a core now; discard the 2-thread figures");
  }
  // The probes of the paired runs sample the whole run, not one moment of it.
  for (const std::string p : {"float", "double"}) {
    const auto fma = results.find(scaling_run(p, results.isa()), "fma_scaling");
    if (fma && fma->median < kRealCores) {
      std::printf("but the FMA probes of the %s pairs scaled only %.2fx (median): the vCPUs shared a core "
                  "for much of the run; trust only the paired figures\n", p.c_str(), fma->median);
    }
  }
}

// The largest state the run streamed on 1 thread (DRAM at 4M bodies), 0 for none.
long stream_size(const Results& results) {
  for (long n : {4194304L, 1048576L, 100000L, 65536L, 16384L, 4096L, 1024L}) {
    if (state_stream(results, "float", n, 1)) return n;
  }
  return 0;
}

std::string size_label(long n) {
  if (n >= (1L << 20) && n % (1L << 20) == 0) return std::to_string(n >> 20) + "M";
  if (n >= 1000 && n % 1000 == 0) return std::to_string(n / 1000) + "k";
  return std::to_string(n);
}

}  // namespace

void print_paired_scaling(const Results& results) {
  bool header = false;
  for (const std::string p : {"float", "double"}) {
    const std::string run = scaling_run(p, results.isa());
    if (!results.find(run, "scaling_all_pairs")) continue;
    if (!header) print_paired_header(results.isa());
    header = true;
    print_paired_row(results, p, run);
  }
}

void print_limits(const Results& results) {
  const long n = stream_size(results);
  if (!fma_peak(results, "float", 1) && n == 0) return;
  const auto peak = [&](const char* p, int threads) { return cell(median(fma_peak(results, p, threads)), "%.1f"); };
  const auto stream = [&](int threads) { return cell(median(state_stream(results, "float", n, threads)), "%.1f"); };
  std::printf("\nMachine limits in this run: FMA peak float %s / %s GFLOP/s (1 / 2 threads), double %s / %s;"
              "\n  the state stream at %s float bodies (%s): %s / %s GB/s (2 threads: Google Benchmark averages each "
              "thread's own time, so a limit measured on threads that did not overlap reads high)\n",
              peak("float", 1).c_str(), peak("float", 2).c_str(), peak("double", 1).c_str(), peak("double", 2).c_str(),
              size_label(n).c_str(), results.isa().c_str(), stream(1).c_str(), stream(2).c_str());
  print_scaling_check(results);
}

}  // namespace kinema::bench::report
