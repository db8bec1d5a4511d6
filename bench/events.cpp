// What events cost (kinema/events.hpp): 100k bodies falling from rest onto a plane under
// gravity, one rk4 step per call (a frame's), without events, with the floor as an event,
// and with four (the floor, a distance, a speed and a user function); and dopri5 (the staged
// path) without events and with the floor, on fixed steps and under advance_to. The heights spread
// over 0.5 .. 500 m, so a few bodies in a thousand cross per step; the set is put back
// every 4 simulated seconds. far-plane: a plane no body reaches (the kernel's test alone). Same bodies, same run, 1 thread at the best ISA. Rigid bodies
// (rigid-float, rigid-double) fall the same way, turning, on the fused rigid kernel: off and
// floor.
#include <benchmark/benchmark.h>

#include <functional>
#include <string>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

constexpr std::int64_t kRestoreSteps = 240;

template <class T>
const ParticleSet<T>& falling_bodies(std::size_t n) {
  return cached<ParticleSet<T>>(n, [](std::size_t count) {
    ParticleSet<T> b;
    b.reserve(count);
    for (std::size_t i = 0; i < count; ++i) {
      const double spread = double((i * 7919) % count) / double(count);  // a fixed shuffle of 0 .. 1
      b.add({T(i % 317), T(0.5 + 499.5 * spread), T(i % 211)}, {}, T(1));
    }
    return b;
  });
}

enum class Watch { none, floor, far, four };

template <class T>
EventOptions<T> watched(Watch w) {
  EventOptions<T> o;
  if (w == Watch::none) return o;
  if (w == Watch::far) {  // a plane no body reaches: the kernel's test alone, nothing to locate
    o.events.push_back({PlaneEvent{{0, 1, 0}, -1e6}, Crossing::down});
    return o;
  }
  o.events.push_back({PlaneEvent{{0, 1, 0}, 0}, Crossing::down});
  if (w == Watch::floor) return o;
  o.events.push_back({DistanceEvent{{150, 250, 100}, 20}, Crossing::either});
  o.events.push_back({SpeedEvent{90}, Crossing::up});
  o.events.push_back({EventFunction<T>([](const EventBlock<T>& b, T* value) {
                        for (std::size_t i = 0; i < b.count; ++i) value[i] = b.px[i] - T(400);
                      }),
                      Crossing::either});
  return o;
}

// The falling bodies, their start kept for restore, and a stepper under gravity watching w.
template <class T>
struct Falling {
  const ParticleSet<T>& initial;
  ParticleSet<T> bodies;
  Stepper<T> stepper;
  Falling(std::size_t n, Watch w, const Method& method)
      : initial(falling_bodies<T>(n)), bodies(initial), stepper(gravity(), method, on_calling_thread()) {
    stepper.set_events(watched<T>(w));
  }
  static ForceModel<T> gravity() {
    ForceModel<T> f;
    f.add(Gravity{{0, kGravity, 0}});
    return f;
  }
};

template <class T>
void falling_step(benchmark::State& state, Watch w, const Method& method) {
  const auto n = std::size_t(state.range(0));
  Falling<T> run(n, w, method);
  run.stepper.step(run.bodies, T(kDt));
  std::int64_t k = 0;
  double hits = 0;
  for (auto _ : state) {
    if (++k % kRestoreSteps == 0) restore(run.bodies, run.initial);
    run.stepper.step(run.bodies, T(kDt));
    hits += double(run.stepper.event_hits().size());
    benchmark::ClobberMemory();
  }
  require_finite(state, run.bodies);
  report_body_steps(state, double(n), particle_step_bytes<T>());
  state.counters["hits_per_step"] = hits / double(state.iterations());
}

// The falling bodies as rigid bodies, each turning about its own axis.
template <class T>
const RigidBodySet<T>& falling_rigid_bodies(std::size_t n) {
  return cached<RigidBodySet<T>>(n, [](std::size_t count) {
    const ParticleSet<T>& centres = falling_bodies<T>(count);
    RigidBodySet<T> b;
    for (std::size_t i = 0; i < count; ++i) {
      const T turn = T(0.1) * T(i % 7);
      b.add({centres.position(i), {}, {1, 0, 0, 0}, {turn, T(0.2), T(-0.3)}, T(1), {T(0.5), T(0.8), T(1.1)}});
    }
    return b;
  });
}

template <class T>
void falling_rigid_step(benchmark::State& state, Watch w) {
  const auto n = std::size_t(state.range(0));
  const RigidBodySet<T>& initial = falling_rigid_bodies<T>(n);
  RigidBodySet<T> bodies = initial;
  Stepper<T> stepper(Falling<T>::gravity(), rk4, on_calling_thread());
  stepper.set_events(watched<T>(w));
  stepper.step(bodies, T(kDt));
  std::int64_t k = 0;
  double hits = 0;
  for (auto _ : state) {
    if (++k % kRestoreSteps == 0) bodies = initial;  // same capacity: no allocation
    stepper.step(bodies, T(kDt));
    hits += double(stepper.event_hits().size());
    benchmark::ClobberMemory();
  }
  if (!all_finite(bodies)) state.SkipWithError("state is not finite after the run");
  report_body_steps(state, double(n), rigid_step_bytes<T>());
  state.counters["hits_per_step"] = hits / double(state.iterations());
}

// A frame's advance_to under dopri5 (error control, rtol = atol = 1e-6), watched as above:
// per body-step of the steps it accepted.
template <class T>
void falling_adaptive(benchmark::State& state, Watch w) {
  const auto n = std::size_t(state.range(0));
  Falling<T> run(n, w, dopri5);
  const Tolerances tol{1e-6, 1e-6};
  run.stepper.advance_to(run.bodies, kDt, tol);
  std::int64_t k = 0;
  double hits = 0, accepted = 0;
  for (auto _ : state) {
    if (++k % kRestoreSteps == 0) restore(run.bodies, run.initial), run.stepper.set_time(0);
    accepted += double(run.stepper.advance_to(run.bodies, run.stepper.time() + kDt, tol).accepted);
    hits += double(run.stepper.event_hits().size());
    benchmark::ClobberMemory();
  }
  require_finite(state, run.bodies);
  report_body_steps(state, double(n) * accepted / double(state.iterations()), particle_step_bytes<T>());
  state.counters["hits_per_step"] = hits / std::max(accepted, 1.0);
}

// rk4 on the fused path (off, floor, four); dopri5 on the staged path (dopri5-off,
// dopri5-floor), where each step keeps its start and is scanned whole; a frame's advance_to
// (adaptive-off, adaptive-floor); rigid bodies on the fused rigid kernel (off, floor).
void register_all() {
  const std::string isa(isa_name(best_isa()));
  const auto add = [&](const std::string& name, Watch w, const Method& method) {
    for (auto* b : {benchmark::RegisterBenchmark(("events/float/" + name + "/" + isa).c_str(), falling_step<float>,
                                                 w, std::cref(method)),
                    benchmark::RegisterBenchmark(("events/double/" + name + "/" + isa).c_str(), falling_step<double>,
                                                 w, std::cref(method))}) {
      b->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
    }
  };
  add("off", Watch::none, rk4);
  add("floor", Watch::floor, rk4);
  add("far-plane", Watch::far, rk4);
  add("four", Watch::four, rk4);
  add("dopri5-off", Watch::none, dopri5);
  add("dopri5-floor", Watch::floor, dopri5);
  for (Watch w : {Watch::none, Watch::floor}) {
    const std::string name = w == Watch::none ? "off" : "floor";
    for (auto* b : {benchmark::RegisterBenchmark(("events/rigid-float/" + name + "/" + isa).c_str(), falling_rigid_step<float>, w),
                    benchmark::RegisterBenchmark(("events/rigid-double/" + name + "/" + isa).c_str(), falling_rigid_step<double>, w)}) {
      b->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
    }
  }
  for (Watch w : {Watch::none, Watch::floor}) {
    const std::string name = w == Watch::none ? "adaptive-off" : "adaptive-floor";
    for (auto* b : {benchmark::RegisterBenchmark(("events/float/" + name + "/" + isa).c_str(), falling_adaptive<float>, w),
                    benchmark::RegisterBenchmark(("events/double/" + name + "/" + isa).c_str(), falling_adaptive<double>, w)}) {
      b->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
    }
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
