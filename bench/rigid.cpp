// kinema's rigid-body path: the particle benchmark's scene with orientation and angular
// momentum added (plus angular drag), step by step and temporally blocked.
#include <benchmark/benchmark.h>

#include <string>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

// Floating-point operations per body-step of the rk4 kernel this scene takes (no point
// forces, no central term): 168 FMAs (2 each), 121 multiplies, 88 adds, 43 subtracts, 8
// divisions and 1 square root (the renormalization), float and double alike, counted in the
// kernel's AVX-512 loop; every value goes through the same operations whatever the order of
// its passes. By hand: 472 for the orientation (94 + 3 x 108 over the stages, 42 to combine
// them, 12 to renormalize).
constexpr double kRigidRk4Flops = 597;

template <class T>
const RigidBodySet<T>& cached_rigid(std::size_t count) {
  return cached<RigidBodySet<T>>(count, [](std::size_t n) { return make_rigid_bodies<T>(rigid_bench_scene(n)); });
}

template <class T>
void rigid_steps(benchmark::State& state, unsigned threads, bool blocked) {
  const auto n = std::size_t(state.range(0));
  const Scene scene = rigid_bench_scene(n);
  RigidBodySet<T> bodies = cached_rigid<T>(n);
  CaseJobs jobs(threads);
  StepperOptions o;
  o.jobs = jobs.get();
  o.workers = WorkerChoice::all;  // n threads, not the measured choice (frame_loop times that)
  Stepper<T> stepper(make_forces<T>(scene), rk4, o);
  const std::uint64_t steps = blocked ? 64 : 1;
  stepper.advance(bodies, T(kDt), 1);
  for (auto _ : state) {
    stepper.advance(bodies, T(kDt), steps);
    benchmark::ClobberMemory();
  }
  if (!all_finite(bodies)) state.SkipWithError("state is not finite after the run");
  report_body_steps(state, double(n) * double(steps), rigid_step_bytes<T>());
  state.counters["GFLOP_per_s"] = benchmark::Counter(
      kRigidRk4Flops * 1e-9 * double(n) * double(steps) * double(state.iterations()), benchmark::Counter::kIsRate);
}

void register_all() {
  const std::string isa(isa_name(best_isa()));
  for (unsigned threads : {1u, 2u}) {
    const std::string suffix = "/" + isa + "/threads:" + std::to_string(threads);
    auto* f = benchmark::RegisterBenchmark(("rigid/rk4/float" + suffix).c_str(),
                                           rigid_steps<float>, threads, false);
    auto* d = benchmark::RegisterBenchmark(("rigid/rk4/double" + suffix).c_str(),
                                           rigid_steps<double>, threads, false);
    for (auto* b : {f, d}) {
      for (std::int64_t n : {1 << 10, 100000, 1 << 22}) b->Arg(n);
      b->UseRealTime()->Unit(benchmark::kMicrosecond);
    }
    for (auto* b : {benchmark::RegisterBenchmark(("rigid-ceiling/rk4/float" + suffix).c_str(),
                                                 rigid_steps<float>, threads, true),
                    benchmark::RegisterBenchmark(("rigid-ceiling/rk4/double" + suffix).c_str(),
                                                 rigid_steps<double>, threads, true)}) {
      b->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
    }
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
