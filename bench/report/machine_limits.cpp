#include "machine_limits.hpp"

#include <algorithm>

#include "names.hpp"

namespace kinema::bench::report {

std::optional<Figure> state_stream(const Results& results, const std::string& p, long n, int threads) {
  std::optional<Figure> best;
  for (long ahead : {0L, 1024L, 4096L}) {
    auto f = results.find(state_stream_run(p, n, ahead, threads), "GB_per_s");
    if (!f) continue;
    f->median = std::max(f->median, f->max);
    if (!best || f->median > best->median) best = f;
  }
  return best;
}

std::optional<Figure> fma_peak(const Results& results, const std::string& p, int threads) {
  return results.find(peak_run(p, threads), "GFLOP_per_s");
}

std::string memory_level(const Results& results, const std::string& p, long n) {
  const auto& caches = results.context().caches;
  if (caches.empty()) return "memory";  // the run could not read the cache sizes
  const double bytes = 7 * value_bytes(p) * double(n);
  for (const auto& [l, size] : caches) {
    if (l >= 2 && bytes <= size) return l == 2 ? "L2" : l == 3 ? "L3" : "L4";
  }
  return "DRAM";
}

}  // namespace kinema::bench::report
