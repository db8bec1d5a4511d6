// Particle tables: fused rk4 against the baselines and limits, every method, every ISA.
#include <cstdio>

#include "csv.hpp"
#include "names.hpp"
#include "rk4_row.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

const char* const kMethods[] = {"euler", "midpoint", "heun", "rk4", "symplectic_euler", "velocity_verlet"};

void print_rk4_row(const Rk4Row& r) {
  const auto one = std::optional<Figure>(r.one);
  std::printf("%-6s %8ld | %7.3f ±%2.0f%% %7s %8s %8s %6s | %12s %7s %6s\n", r.p.c_str(), r.n, r.one.median,
              100 * r.one.cv, cell(ratio(r.naive, one), "%.1fx").c_str(), cell(ratio(r.odeint, one), "%.1fx").c_str(),
              cell(percent(ratio(r.ceiling, one)), "%.0f%%").c_str(), cell(percent(r.bandwidth_one), "%.0f%%").c_str(),
              cell(median(r.two), "%.3f").c_str(), cell(ratio(one, r.two), "%.2fx").c_str(),
              cell(percent(r.bandwidth_two), "%.0f%%").c_str());
}

void print_rk4_notes(const std::string& isa) {
  std::printf("ceiling: the same kernel with its memory traffic removed (each cache-resident block "
              "takes all steps in turn), as ceiling time / step time.\nBW: state bytes read + "
              "written per second against the state's own stream (the same 7 arrays read and 6 "
              "written, almost no arithmetic, %s; the best repetition at the fastest of three prefetch distances) at the same size, precision and thread count.\n"
              "2 threads: every step on both (workers = all); at N = 1024 the set is one block, "
              "run on the calling thread.\n", isa.c_str());
}

}  // namespace

void print_rk4_table(const Results& results, Noise& noise, Rk4Csv* csv) {
  std::printf("\nFused RK4 (gravity + linear drag + spring), %s, ns per body-step; ratios from this run\n",
              results.isa().c_str());
  std::printf("%-6s %8s | %12s %7s %7s %8s %6s | %12s %7s %6s\n", "prec", "N", "1 thread",
              "x naive", "x odeint", "ceiling", "BW", "2 threads", "scaling", "BW");
  for (const std::string p : {"float", "double"}) {
    for (long n : {1024L, 16384L, 100000L, 1048576L, 4194304L}) {
      const auto row = rk4_row(results, p, n);
      if (!row) continue;
      noise.add(row->one.cv);
      print_rk4_row(*row);
      if (csv != nullptr) csv->write(*row);
    }
  }
  print_rk4_notes(results.isa());
}

void print_methods_table(const Results& results) {
  const std::string& isa = results.isa();
  std::printf("\nEvery method, N = 100000, 1 thread, %s: ns per body-step (ceiling fraction)\n", isa.c_str());
  for (const std::string p : {"float", "double"}) {
    std::printf("%-6s", p.c_str());
    for (const char* m : kMethods) {
      const auto f = results.find(kernel_run("fused", m, p, isa, 1, 100000), "ns_per_body_step");
      const auto c = results.find(kernel_run("ceiling", m, p, isa, 1, 100000), "ns_per_body_step");
      std::printf("  %s %s (%s)", m, cell(median(f), "%.3f").c_str(), cell(percent(ratio(c, f)), "%.0f%%").c_str());
    }
    std::printf("\n");
  }
}

void print_isa_table(const Results& results) {
  std::printf("\nRK4, N = 100000, 1 thread, by instruction set: ns per body-step (speed-up over scalar)\n");
  for (const std::string p : {"float", "double"}) {
    const auto scalar = results.find(kernel_run("fused", "rk4", p, "scalar", 1, 100000), "ns_per_body_step");
    std::printf("%-6s", p.c_str());
    for (const char* isa : {"scalar", "sse2", "avx2", "avx512"}) {
      const auto f = results.find(kernel_run("fused", "rk4", p, isa, 1, 100000), "ns_per_body_step");
      if (!f) continue;
      std::printf("  %s %.3f (%s)", isa, f->median, cell(ratio(scalar, f), "%.1fx").c_str());
    }
    std::printf("\n");
  }
}

}  // namespace kinema::bench::report
