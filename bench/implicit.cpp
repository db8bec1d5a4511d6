// Implicit methods on two 256 x 256 cloths (65536 bodies): `cloth`, the shipped cloth's springs
// and masses (k 400, mass 0.001: the same stiffness, |lambda| about 1790/s) on a grid of
// spacing 0.005, and `cloth-4x`, the shipped cloth itself at four times its resolution (the
// same size, springs and total mass: a sixteenth of the mass and drag a body, |lambda| four
// times as large). Steps of 1/60 s under implicit_euler and ros2 (the default preconditioner:
// multigrid) and implicit_euler with Jacobi's, against velocity Verlet (the cheapest explicit
// method per step) at its largest stable step, per simulated second, one thread; and one
// Jacobi conjugate-gradient iteration's traffic against in-place streaming over as many
// bytes (limit/stream at kCgStreamBodies, bench/machine.cpp).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <string>

#include "bench_scene.hpp"
#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"

namespace kinema::bench {
namespace {

constexpr double kFrame = 1.0 / 60;

Scene cloth_scene(double mass, double drag) {
  char text[600];
  std::snprintf(text, sizeof text, R"({"precision": "float", "method": "ros2", "dt": 0.016666666666666666, "steps": 1,
    "forces": [{"type": "gravity", "g": [0, -9.81, 0]}, {"type": "linear_drag", "k": %.17g},
      {"type": "springs", "grid": {"rows": 256, "columns": 256, "spacing": 0.005, "k": 400, "damping": 0.02,
       "mass": %.17g, "origin": [0, 1, 0], "pinned": "top_corners"}}]})", drag, mass);
  return parse_scene(text);
}

struct Cloth {
  ParticleSet<float> bodies;  // after the first frames, swinging
  ForceModel<float> forces;
  double slots_per_body = 0;  // the spring network's slots (lanes of its entries) per body
};

// fine: the cloth-4x cloth.
const Cloth& cloth(bool fine) {
  return cached<Cloth>(fine ? 4 : 1, [](std::size_t refined) {
    const double per_body = 1.0 / double(refined * refined);
    const Scene scene = cloth_scene(0.001 * per_body, 0.0005 * per_body);
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

struct ImplicitRow {
  const Method* method;
  ImplicitPreconditioner preconditioner;
  bool fine;
  double tolerance = 0;  // the default (1e-3 in float)
};

// Frames of 1/60 s from the swinging cloth (each iteration goes on from the last).
void implicit_frames(benchmark::State& state, ImplicitRow row) {
  const Cloth& c = cloth(row.fine);
  ParticleSet<float> bodies = c.bodies;
  StepperOptions options = on_calling_thread();
  options.implicit_preconditioner = row.preconditioner;
  options.implicit_tolerance = row.tolerance;
  Stepper<float> stepper(c.forces, *row.method, options);
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
  if (row.preconditioner != ImplicitPreconditioner::jacobi) return;
  state.counters["GB_per_s"] = Counter(iterations * n * cg_bytes_per_body(c.slots_per_body) * 1e-9, Counter::kIsRate);
}

// Velocity Verlet at 0.8 of the largest stable step predicted at the start (0.9 ms on
// `cloth`, 0.2 ms on `cloth-4x`): the
// stretched, swinging cloth is stiffer than at rest, and 0.95 of it blows up within 0.4 s.
void explicit_frames(benchmark::State& state, bool fine) {
  const Cloth& c = cloth(fine);
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
  using P = ImplicitPreconditioner;
  for (const bool fine : {false, true}) {
    const std::string scene = fine ? "implicit/cloth-4x/" : "implicit/cloth/";
    // At 1e-2 a solve moves the 64 x 64 cloth by 9-13 mm in its first 2 s, where the step
    // itself is 47-201 mm from a fine explicit run (bench/README.md#implicit-methods); 1e-5
    // was float's default before 1e-3.
    for (const ImplicitRow row : {ImplicitRow{&implicit_euler, P::automatic, fine}, {&implicit_euler, P::jacobi, fine},
                                  {&implicit_euler, P::automatic, fine, 1e-2}, {&implicit_euler, P::automatic, fine, 1e-5},
                                  {&ros2, P::automatic, fine}}) {
      const std::string tolerance = row.tolerance == 1e-2 ? "-tol-0.01" : row.tolerance == 1e-5 ? "-tol-1e-5" : "";
      const std::string name =
          std::string(row.method->name) + (row.preconditioner == P::jacobi ? "-jacobi" : "") + tolerance;
      benchmark::RegisterBenchmark((scene + name + "/256").c_str(), implicit_frames, row)
          ->UseRealTime()->Unit(benchmark::kMillisecond);
    }
    benchmark::RegisterBenchmark((scene + "velocity_verlet/256").c_str(), explicit_frames, fine)
        ->UseRealTime()->Unit(benchmark::kMillisecond);
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
