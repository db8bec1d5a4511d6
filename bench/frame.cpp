// A frame as an engine runs it at 60 Hz: keep the previous state, one step, interpolate for
// drawing; against a plain copy of the same set measured in the same run.
#include <benchmark/benchmark.h>

#include <cstring>
#include <string>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

template <class T>
void frame(benchmark::State& state, Isa isa) {
  const auto n = std::size_t(state.range(0));
  ParticleSet<T> current = cached_particles<T>(n), previous = current, drawn = current;
  StepperOptions o = on_calling_thread();
  o.isa = isa;
  Stepper<T> stepper(make_forces<T>(bench_scene(n)), rk4, o);
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % kRestoreEvery == 0) restore(current, cached_particles<T>(n));
    previous = current;
    stepper.step(current, T(kDt));
    interpolate(previous, current, T(0.5), drawn, isa);
    benchmark::ClobberMemory();
  }
  require_finite(state, drawn);
  report_body_steps(state, double(n), particle_step_bytes<T>());
  state.SetLabel(std::string(isa_name(stepper.isa())));
}

// previous = current alone: the bytes a frame must at least copy once.
template <class T>
void copy(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  const ParticleSet<T>& current = cached_particles<T>(n);
  ParticleSet<T> previous = current;
  for (auto _ : state) {
    previous = current;
    benchmark::ClobberMemory();
  }
  report_body_steps(state, double(n), 14.0 * sizeof(T));
}

void register_all() {
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    const std::string name(isa_name(isa));
    benchmark::RegisterBenchmark(("frame/float/" + name).c_str(), frame<float>, isa)
        ->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark(("frame/double/" + name).c_str(), frame<double>, isa)
        ->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
  }
  benchmark::RegisterBenchmark("frame/copy/float", copy<float>)->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("frame/copy/double", copy<double>)->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
