#pragma once
// The machine's limits as the run measured them: the state stream (the memory bound of a
// particle step) and the FMA peak, and where a state of n bodies lives.
#include <optional>
#include <string>

#include "results.hpp"

namespace kinema::bench::report {

inline double value_bytes(const std::string& p) { return p == "float" ? 4 : 8; }

// The state stream's limit: its best repetition at the fastest of its prefetch distances
// (none, 1 KiB, 4 KiB), GB/s.
std::optional<Figure> state_stream(const Results& results, const std::string& p, long n, int threads);

// The FMA peak of a precision at a thread count, GFLOP/s.
std::optional<Figure> fma_peak(const Results& results, const std::string& p, int threads);

// Where a state of n bodies of precision p lives: the smallest data cache holding it, DRAM,
// or "memory" when the run did not know its caches.
std::string memory_level(const Results& results, const std::string& p, long n);

}  // namespace kinema::bench::report
