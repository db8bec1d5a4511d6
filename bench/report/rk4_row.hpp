#pragma once
// The headline row: fused rk4 at one size against the baselines and the machine's limits,
// computed once for the table and the CSV.
#include <optional>
#include <string>

#include "results.hpp"

namespace kinema::bench::report {

struct Rk4Row {
  std::string p;
  long n = 0;
  Figure one;                                        // 1 thread, ns per body-step
  std::optional<Figure> two, naive, odeint, ceiling;  // ns per body-step
  std::optional<double> bandwidth_one, bandwidth_two;  // share of the state stream
};

// The row at precision p and n bodies, when the run has fused rk4 there on 1 thread.
std::optional<Rk4Row> rk4_row(const Results& results, const std::string& p, long n);

}  // namespace kinema::bench::report
