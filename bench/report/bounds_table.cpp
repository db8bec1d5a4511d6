// What bounds each method at each size: the compute ceiling or the state stream at that
// size, whichever is slower, and the share of it reached.
#include <cstdio>
#include <string>
#include <vector>

#include "machine_limits.hpp"
#include "names.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

const long kSizes[] = {16384L, 100000L, 4194304L};

struct Bound {
  Figure step;           // ns per body-step
  double ceiling_ns;     // the kernel with its traffic removed
  double memory_ns;      // the state's bytes at the state stream's speed
  double bound_ns;       // the slower of the two
  std::string kind;      // "compute" or where the state lives
  double share() const { return bound_ns / step.median; }
};

std::optional<Bound> bound_at(const Results& results, const std::string& p, const char* m, long n) {
  const auto f = results.find(kernel_run("fused", m, p, results.isa(), 1, n), "ns_per_body_step");
  const auto c = results.find(kernel_run("ceiling", m, p, results.isa(), 1, 100000), "ns_per_body_step");
  const auto s = state_stream(results, p, n, 1);
  if (!f || !c || !s) return std::nullopt;
  const double memory_ns = 13 * value_bytes(p) / s->median;
  const bool compute = c->median >= memory_ns;
  return Bound{*f, c->median, memory_ns, compute ? c->median : memory_ns,
               compute ? "compute" : memory_level(results, p, n)};
}

std::string below_70_line(const Bound& b, const std::string& p, const char* m, long n) {
  char line[256];
  std::snprintf(line, sizeof line, "below 70%%: %s %s at %ld: %.3f ns against %s %.3f (ceiling %.3f, state stream %.3f)",
                p.c_str(), m, n, b.step.median, b.kind.c_str(), b.bound_ns, b.ceiling_ns, b.memory_ns);
  return line;
}

// One method's row; the cells below 70% of their bound are named in `below_70`.
void print_bounds_row(const Results& results, Noise& noise, const std::string& p, const char* m,
                      std::vector<std::string>& below_70) {
  std::printf("%-6s %-16s", p.c_str(), m);
  for (long n : kSizes) {
    const auto b = bound_at(results, p, m, n);
    if (!b) {
      std::printf(" | %26s", "-");
      continue;
    }
    noise.add(b->step.cv);
    std::printf(" | %14.3f %7s %4.0f", b->step.median, b->kind.c_str(), 100 * b->share());
    if (b->share() < 0.7) below_70.push_back(below_70_line(*b, p, m, n));
  }
  std::printf("\n");
}

}  // namespace

void print_bounds_table(const Results& results, Noise& noise) {
  if (!results.find(kernel_run("fused", "euler", "float", results.isa(), 1, 4194304), "ns_per_body_step")) return;
  const char* levels = results.context().caches.empty() ? "memory (the run did not know the cache sizes)" : "L2 / L3 / DRAM";
  std::printf("\nWhat bounds each method, 1 thread, %s: ns per body-step, the bound (compute: the ceiling; "
              "%s: the state stream at that size) and the share of it reached\n", results.isa().c_str(), levels);
  std::printf("%-6s %-16s", "prec", "method");
  for (long n : kSizes) std::printf(" | %8ld: ns   bound    %%", n);
  std::printf("\n");
  std::vector<std::string> below_70;
  for (const std::string p : {"float", "double"}) {
    for (const char* m : kMethods) {
      print_bounds_row(results, noise, p, m, below_70);
    }
  }
  for (const std::string& line : below_70) std::printf("%s\n", line.c_str());
}

}  // namespace kinema::bench::report
