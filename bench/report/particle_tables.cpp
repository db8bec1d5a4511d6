// Particle tables: fused rk4 against the baselines and limits, every method, every ISA.
#include <cstdio>
#include <string>
#include <vector>

#include "csv.hpp"
#include "names.hpp"
#include "rk4_row.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

const char* const kIsas[] = {"scalar", "sse2", "avx2", "avx512"};

void print_rk4_row(const Rk4Row& r) {
  const auto one = std::optional<Figure>(r.one);
  std::printf("%-6s %8ld | %7.3f ±%2.0f%% %7s %8s %8s %6s | %12s %7s %6s\n", r.p.c_str(), r.n, r.one.median,
              100 * r.one.cv, cell(ratio(r.naive, one), "%.1fx").c_str(), cell(ratio(r.odeint, one), "%.1fx").c_str(),
              cell(percent(ratio(r.ceiling, one)), "%.0f%%").c_str(), cell(percent(r.bandwidth_one), "%.0f%%").c_str(),
              cell(median(r.two), "%.3f").c_str(), cell(ratio(one, r.two), "%.2fx").c_str(),
              cell(percent(r.bandwidth_two), "%.0f%%").c_str());
}

void print_rk4_notes(const std::string& isa, bool one_block_row) {
  std::printf("ceiling: the same kernel with its memory traffic removed (each cache-resident block "
              "takes all steps in turn), as ceiling time / step time.\nBW: state bytes read + "
              "written per second against the state's own stream (the same 7 arrays read and 6 "
              "written, almost no arithmetic, %s; the best repetition at the fastest of three prefetch distances) at the same size, precision and thread count.\n"
              "2 threads: every step on both (workers = all)%s\n", isa.c_str(),
              one_block_row ? "; at N = 1024 the set is one block, run on the calling thread." : ".");
}

std::vector<Rk4Row> rk4_rows(const Results& results) {
  std::vector<Rk4Row> rows;
  for (const std::string p : {"float", "double"}) {
    for (long n : {1024L, 16384L, 100000L, 1048576L, 4194304L}) {
      if (auto row = rk4_row(results, p, n)) rows.push_back(std::move(*row));
    }
  }
  return rows;
}

// A method's figure at N = 100000 on 1 thread.
std::optional<Figure> method_step(const Results& results, const char* kind, const char* m, const std::string& p) {
  return results.find(kernel_run(kind, m, p, results.isa(), 1, 100000), "ns_per_body_step");
}

// A table of methods says more than the rk4 table only when another method was run.
bool has_other_methods(const Results& results) {
  for (const std::string p : {"float", "double"}) {
    for (const char* m : kMethods) {
      if (std::string(m) != "rk4" && method_step(results, "fused", m, p)) return true;
    }
  }
  return false;
}

int isas_with_rk4(const Results& results) {
  int count = 0;
  for (const char* isa : kIsas) {
    for (const std::string p : {"float", "double"}) {
      if (results.find(kernel_run("fused", "rk4", p, isa, 1, 100000), "ns_per_body_step")) {
        ++count;
        break;
      }
    }
  }
  return count;
}

}  // namespace

void print_rk4_table(const Results& results, Noise& noise, Rk4Csv* csv) {
  const std::vector<Rk4Row> rows = rk4_rows(results);
  if (rows.empty()) return;
  std::printf("\nFused RK4 (gravity + linear drag + spring), %s, ns per body-step; ratios from this run\n",
              results.isa().c_str());
  std::printf("%-6s %8s | %12s %7s %7s %8s %6s | %12s %7s %6s\n", "prec", "N", "1 thread",
              "x naive", "x odeint", "ceiling", "BW", "2 threads", "scaling", "BW");
  bool one_block_row = false;
  for (const Rk4Row& row : rows) {
    noise.add(row.one.cv);
    print_rk4_row(row);
    if (csv != nullptr) csv->write(row);
    one_block_row = one_block_row || row.n == 1024;
  }
  print_rk4_notes(results.isa(), one_block_row);
}

void print_methods_table(const Results& results) {
  if (!has_other_methods(results)) return;
  std::printf("\nEvery method, N = 100000, 1 thread, %s: ns per body-step (ceiling fraction)\n", results.isa().c_str());
  for (const std::string p : {"float", "double"}) {
    std::printf("%-6s", p.c_str());
    for (const char* m : kMethods) {
      const auto f = method_step(results, "fused", m, p);
      const auto c = method_step(results, "ceiling", m, p);
      std::printf("  %s %s (%s)", m, cell(median(f), "%.3f").c_str(), cell(percent(ratio(c, f)), "%.0f%%").c_str());
    }
    std::printf("\n");
  }
}

void print_isa_table(const Results& results) {
  if (isas_with_rk4(results) < 2) return;
  std::printf("\nRK4, N = 100000, 1 thread, by instruction set: ns per body-step (speed-up over scalar)\n");
  for (const std::string p : {"float", "double"}) {
    const auto scalar = results.find(kernel_run("fused", "rk4", p, "scalar", 1, 100000), "ns_per_body_step");
    std::printf("%-6s", p.c_str());
    for (const char* isa : kIsas) {
      const auto f = results.find(kernel_run("fused", "rk4", p, isa, 1, 100000), "ns_per_body_step");
      if (!f) continue;
      std::printf("  %s %.3f (%s)", isa, f->median, cell(ratio(scalar, f), "%.1fx").c_str());
    }
    std::printf("\n");
  }
}

}  // namespace kinema::bench::report
