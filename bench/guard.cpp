// What the finiteness guard costs: one fused rk4 step per iteration (a frame loop's call)
// with the guard off, check and clamp, on the same bodies in the same run.
#include <benchmark/benchmark.h>

#include <string>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

template <class T>
void guarded_step(benchmark::State& state, Isa isa, FiniteGuard guard) {
  const auto n = std::size_t(state.range(0));
  ParticleSet<T> bodies = cached_particles<T>(n);
  StepperOptions o = on_calling_thread();
  o.isa = isa;
  o.guard = guard;
  Stepper<T> stepper(make_forces<T>(bench_scene(n)), rk4, o);
  stepper.step(bodies, T(kDt));  // the guard's copy is allocated at the first step
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % kRestoreEvery == 0) restore(bodies, cached_particles<T>(n));
    stepper.step(bodies, T(kDt));
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_body_steps(state, double(n), particle_step_bytes<T>());
}

void register_all() {
  const Isa isa = best_isa();
  for (const auto& [name, guard] : {std::pair{"off", FiniteGuard::off}, std::pair{"check", FiniteGuard::check},
                                    std::pair{"clamp", FiniteGuard::clamp}}) {
    const std::string suffix = std::string(name) + "/" + std::string(isa_name(isa));
    for (auto* b : {benchmark::RegisterBenchmark(("guard/float/" + suffix).c_str(), guarded_step<float>, isa, guard),
                    benchmark::RegisterBenchmark(("guard/double/" + suffix).c_str(), guarded_step<double>, isa, guard)}) {
      b->Arg(100000)->Arg(1 << 20)->UseRealTime()->Unit(benchmark::kMicrosecond);
    }
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
