// The error-controlled driver against fixed steps of the same method: dopri5 at 100k bodies
// on one thread, the fixed run at the driver's mean accepted step, so both take the same
// steps; the difference is the driver's (the saved state, the error estimate, the control).
#include <benchmark/benchmark.h>

#include <string>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

constexpr double kSpan = 0.5;  // simulated seconds per advance_to call

template <class T>
Tolerances tolerances() {
  const double tol = sizeof(T) == 4 ? 1e-5 : 1e-9;
  return {tol, tol};
}

template <class T>
Stepper<T> dopri5_stepper(std::size_t n) {
  return Stepper<T>(make_forces<T>(bench_scene(n)), dopri5, on_calling_thread());
}

// Accepted steps of one advance_to over kSpan from the initial state.
template <class T>
std::uint64_t steps_per_span(std::size_t n) {
  ParticleSet<T> bodies = cached_particles<T>(n);
  Stepper<T> stepper = dopri5_stepper<T>(n);
  return stepper.advance_to(bodies, kSpan, tolerances<T>()).accepted;
}

template <class T>
void adaptive(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  ParticleSet<T> bodies = cached_particles<T>(n);
  Stepper<T> stepper = dopri5_stepper<T>(n);
  stepper.reserve(n);
  std::uint64_t accepted = 0, rejected = 0;
  for (auto _ : state) {
    // Each call from the initial state: the same steps every iteration.
    state.PauseTiming();
    restore(bodies, cached_particles<T>(n));
    stepper.set_time(0);
    state.ResumeTiming();
    const AdaptiveStats s = stepper.advance_to(bodies, kSpan, tolerances<T>());
    accepted += s.accepted, rejected += s.rejected;
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_body_steps(state, double(n) * double(accepted) / double(state.iterations()), particle_step_bytes<T>());
  state.counters["accepted_per_call"] = double(accepted) / double(state.iterations());
  state.counters["rejected_per_call"] = double(rejected) / double(state.iterations());
}

template <class T>
void fixed(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  const std::uint64_t steps = steps_per_span<T>(n);
  ParticleSet<T> bodies = cached_particles<T>(n);
  Stepper<T> stepper = dopri5_stepper<T>(n);
  stepper.reserve(n);
  const T h = T(kSpan / double(steps));
  for (auto _ : state) {
    state.PauseTiming();
    restore(bodies, cached_particles<T>(n));
    state.ResumeTiming();
    stepper.advance(bodies, h, steps);
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_body_steps(state, double(n) * double(steps), particle_step_bytes<T>());
  state.counters["steps_per_call"] = double(steps);
}

void register_all() {
  const std::string isa(isa_name(best_isa()));
  for (auto* b : {benchmark::RegisterBenchmark(("adaptive/dopri5/float/" + isa).c_str(), adaptive<float>),
                  benchmark::RegisterBenchmark(("adaptive/dopri5/double/" + isa).c_str(), adaptive<double>),
                  benchmark::RegisterBenchmark(("fixed/dopri5/float/" + isa).c_str(), fixed<float>),
                  benchmark::RegisterBenchmark(("fixed/dopri5/double/" + isa).c_str(), fixed<double>)}) {
    b->Arg(100000)->UseRealTime()->Unit(benchmark::kMillisecond);
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
