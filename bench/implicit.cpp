// Implicit methods on the shipped cloth's springs and masses (k 400, mass 0.001: the same
// stiffness, |lambda| about 1790/s) on a 256 x 256 grid (65536 bodies): steps of 1/60 s
// under implicit_euler and ros2 against velocity Verlet (the cheapest explicit method per
// step) at its largest stable step, per simulated second, one thread; and one
// conjugate-gradient iteration's traffic against in-place streaming over as many bytes
// (limit/stream at kCgStreamBodies, bench/machine.cpp).
#include <benchmark/benchmark.h>

#include <string>

#include "bench_scene.hpp"
#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"

namespace kinema::bench {
namespace {

constexpr double kFrame = 1.0 / 60;

Scene cloth_scene() {
  return parse_scene(R"({"precision": "float", "method": "ros2", "dt": 0.016666666666666666, "steps": 1,
    "forces": [{"type": "gravity", "g": [0, -9.81, 0]}, {"type": "linear_drag", "k": 0.0005},
      {"type": "springs", "grid": {"rows": 256, "columns": 256, "spacing": 0.005, "k": 400, "damping": 0.02,
       "mass": 0.001, "origin": [0, 1, 0], "pinned": "top_corners"}}]})");
}

struct Cloth {
  ParticleSet<float> bodies;  // after the first frames, swinging
  ForceModel<float> forces;
  double slots_per_body = 0;  // the spring network's slots (lanes of its entries) per body
};

const Cloth& cloth() {
  return cached<Cloth>(256, [](std::size_t) {
    const Scene scene = cloth_scene();
    Cloth c{make_particles<float>(scene), make_forces<float>(scene)};
    Stepper<float>(c.forces, implicit_euler, on_calling_thread()).advance(c.bodies, float(kFrame), 3);
    CoupledForces<float> lowered = lower_coupled<float>(c.forces);
    lowered.springs.lay_out();
    c.slots_per_body = double(lowered.springs.rest.size()) / double(c.bodies.size());
    return c;
  });
}

// Bytes one iteration reads and writes per body: the product (p, mass, q and per slot the
// unit vector and the weights along and across; neighbours' p come from cache, and only
// runs that are not consecutive read their neighbour indices), the update (x, r, p, q, the
// preconditioner, z) and the new direction (z, p).
double cg_bytes_per_body(double slots) { return (3 + 1 + 3) * 4 + slots * 5 * 4 + 24 * 4 + 9 * 4; }

void report_simulated(benchmark::State& state, double h) {
  using benchmark::Counter;
  state.counters["s_per_simulated_s"] = Counter(double(state.iterations()) * h, Counter::kIsRate | Counter::kInvert);
}

// Frames of 1/60 s from the swinging cloth (each iteration goes on from the last).
void implicit_frames(benchmark::State& state, const Method* method) {
  const Cloth& c = cloth();
  ParticleSet<float> bodies = c.bodies;
  Stepper<float> stepper(c.forces, *method, on_calling_thread());
  for (auto _ : state) {
    stepper.step(bodies, float(kFrame));
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_simulated(state, kFrame);
  using benchmark::Counter;
  const ImplicitStats& s = stepper.implicit_stats();
  const double iterations = double(s.iterations), n = double(bodies.size());
  state.counters["cg_per_frame"] = iterations / double(state.iterations());
  // The whole frame over its iterations: an upper bound of one iteration's cost.
  state.counters["ns_per_body_iteration"] = Counter(iterations * n * 1e-9, Counter::kIsRate | Counter::kInvert);
  state.counters["GB_per_s"] = Counter(iterations * n * cg_bytes_per_body(c.slots_per_body) * 1e-9, Counter::kIsRate);
}

// Velocity Verlet at 0.8 of the largest stable step predicted at the start (0.9 ms): the
// stretched, swinging cloth is stiffer than at rest, and 0.95 of it blows up within 0.4 s.
void explicit_frames(benchmark::State& state) {
  const Cloth& c = cloth();
  ParticleSet<float> bodies = c.bodies;
  Stepper<float> stepper(c.forces, velocity_verlet, on_calling_thread());
  const double h = 0.8 * largest_stable_step(velocity_verlet, estimate_stiffness(bodies, c.forces));
  const auto steps = std::uint64_t(kFrame / h) + 1;
  for (auto _ : state) {
    stepper.advance(bodies, float(kFrame / double(steps)), steps);
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_simulated(state, kFrame);
  state.counters["steps_per_frame"] = double(steps);
}

void register_all() {
  for (const Method* m : {&implicit_euler, &ros2}) {
    benchmark::RegisterBenchmark(("implicit/cloth/" + std::string(m->name) + "/256").c_str(), implicit_frames, m)
        ->UseRealTime()->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("implicit/cloth/velocity_verlet/256", explicit_frames)
      ->UseRealTime()->Unit(benchmark::kMillisecond);
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
