#include "rk4_row.hpp"

#include "machine_limits.hpp"
#include "names.hpp"

namespace kinema::bench::report {
namespace {

// Bytes per second of fused rk4 against the state stream at the same size and threads.
std::optional<double> bandwidth_share(const Results& results, const std::string& p, long n, int threads) {
  const auto fused = results.find(kernel_run("fused", "rk4", p, results.isa(), threads, n), "GB_per_s");
  return ratio(fused, state_stream(results, p, n, threads));
}

}  // namespace

std::optional<Rk4Row> rk4_row(const Results& results, const std::string& p, long n) {
  const std::string& isa = results.isa();
  const auto one = results.find(kernel_run("fused", "rk4", p, isa, 1, n), "ns_per_body_step");
  if (!one) return std::nullopt;
  Rk4Row row;
  row.p = p;
  row.n = n;
  row.one = *one;
  row.two = results.find(kernel_run("fused", "rk4", p, isa, 2, n), "ns_per_body_step");
  row.naive = results.find(baseline_run("naive_aos", p, n), "ns_per_body_step");
  row.odeint = results.find(baseline_run("odeint", p, n), "ns_per_body_step");
  row.ceiling = results.find(kernel_run("ceiling", "rk4", p, isa, 1, 100000), "ns_per_body_step");
  row.bandwidth_one = bandwidth_share(results, p, n, 1);
  row.bandwidth_two = bandwidth_share(results, p, n, 2);
  return row;
}

}  // namespace kinema::bench::report
