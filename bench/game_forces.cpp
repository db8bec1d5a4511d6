// Forces from the game, beside the fused rows of the same run: the bench scene (gravity,
// linear drag, a spring) as built-in terms; the same with a force applied to every body; with
// a gravity factor and damping rate per body (and angular damping for rigid bodies); with
// gravity moved into a one-line callback (the block path), as g times the view's mass and as
// g over its inverse mass (a division per body and stage); gravity built in beside a callback
// that adds nothing (what the block path costs by itself); with a coupled term that adds
// nothing (the staged path); and rigid bodies plain, with applied forces and torques, and
// with their angular drag in a one-line callback (the rigid block path), and both in chains
// of 64 joined by springs (spring pairs between particles, body springs between points of
// rigid bodies: the staged paths). Each iteration is one advance of kSteps steps, as a frame
// of a fixed-step loop that catches up, on 1 thread at the best ISA.
#include <benchmark/benchmark.h>

#include <string>
#include <type_traits>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

constexpr std::uint64_t kSteps = 20;

enum class Variant { fused, applied, parameters, callback, callback_divide, callback_empty, staged, springs };

// Chains of 64: body i joined to i + 1 within its chain.
constexpr std::size_t kChain = 64;
bool joined_to_next(std::size_t i, std::size_t n) { return (i + 1) % kChain != 0 && i + 1 < n; }

const char* variant_name(Variant v) {
  switch (v) {
    case Variant::fused: return "fused";
    case Variant::applied: return "applied";
    case Variant::parameters: return "parameters";
    case Variant::callback: return "callback";
    case Variant::callback_divide: return "callback-divide";
    case Variant::callback_empty: return "callback-empty";
    case Variant::staged: return "staged";
    case Variant::springs: return "springs";
  }
  return "";
}

// A coupled term that couples nothing: what the staged path costs by itself.
template <class T>
class NoCoupling final : public CoupledTerm<T> {
 public:
  void accumulate(const ParticleState<T>&, const ParticleBlock<T>&) const override {}
  double potential_energy(const ParticleState<T>&) const override { return 0; }
};

// A gravity factor and a linear damping rate for every body, differing from body to body.
template <class Set>
void set_parameters(Set& bodies) {
  using T = std::decay_t<decltype(bodies.gravity_factor(0))>;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    bodies.set_gravity_factor(i, T(0.5) + T(0.25) * T(i % 3));
    bodies.set_linear_damping(i, T(0.02) * T(i % 5));
  }
}

// The bench scene's model, with gravity taken out of the built-in terms where the variant
// gives it by callback.
template <class T>
ForceModel<T> variant_forces(Variant v, std::size_t n) {
  Scene scene = bench_scene(n);
  const bool by_callback = v == Variant::callback || v == Variant::callback_divide;
  if (by_callback) scene.forces.erase(scene.forces.begin());  // gravity
  ForceModel<T> f = make_forces<T>(scene);
  if (v == Variant::callback) {
    f.add([](ParticleBlock<T> b) {  // by value: the compiler knows its arrays apart
      for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += T(kGravity) * b.mass[i];
    });
  }
  if (v == Variant::callback_divide) {
    f.add([](ParticleBlock<T> b) {
      for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += T(kGravity) / b.inv_mass[i];
    });
  }
  if (v == Variant::callback_empty) f.add([](ParticleBlock<T>) {});  // the block path's own cost
  if (v == Variant::staged) f.add(std::make_shared<const NoCoupling<T>>());
  if (v == Variant::springs) {
    Springs chains;
    for (std::size_t i = 0; i < n; ++i) {
      if (joined_to_next(i, n)) chains.pairs.push_back({std::uint32_t(i), std::uint32_t(i + 1), 0.5, 10, 0.1});
    }
    f.add(std::move(chains));
  }
  return f;
}

template <class T>
void particle_forces(benchmark::State& state, Variant v) {
  const auto n = std::size_t(state.range(0));
  ParticleSet<T> bodies = cached_particles<T>(n);
  const ParticleSet<T>& initial = cached_particles<T>(n);
  CaseJobs jobs(1);
  StepperOptions o;
  o.jobs = jobs.get();
  Stepper<T> stepper(variant_forces<T>(v, n), rk4, o);
  if (v == Variant::applied) {
    bodies.keep_forces(true);  // a game applies them every frame; here once, and kept
    for (std::size_t i = 0; i < n; ++i) bodies.apply_force(i, {T(0.5), T(i % 3), T(-0.25)});
  }
  if (v == Variant::parameters) set_parameters(bodies);
  stepper.advance(bodies, T(kDt), kSteps);  // warm: first touch, scratch
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % (kRestoreEvery / std::int64_t(kSteps)) == 0) restore(bodies, initial);
    stepper.advance(bodies, T(kDt), kSteps);
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_body_steps(state, double(n) * double(kSteps), particle_step_bytes<T>());
}

// The rigid scene's model, its angular drag given by a one-line callback where the variant
// says so.
template <class T>
ForceModel<T> rigid_variant_forces(Variant v, Scene scene, std::size_t n) {
  if (v == Variant::springs) {  // the particle chains' springs, between corners of the bodies
    ForceModel<T> f = make_forces<T>(scene);
    BodySprings chains;
    for (std::size_t i = 0; i < n; ++i) {
      if (joined_to_next(i, n)) chains.springs.push_back({std::uint32_t(i), std::uint32_t(i + 1), {0.2, 0.1, 0}, {-0.2, 0.1, 0}, 0.5, 10, 0.1});
    }
    return f.add(chains);
  }
  if (v != Variant::callback) return make_forces<T>(scene);
  scene.forces.pop_back();  // the angular drag
  ForceModel<T> f = make_forces<T>(scene);
  f.add([](RigidBlock<T> b) {  // by value: the compiler knows its arrays apart
    for (std::size_t i = 0; i < b.count; ++i) b.tx[i] -= T(0.05) * b.wx[i], b.ty[i] -= T(0.05) * b.wy[i], b.tz[i] -= T(0.05) * b.wz[i];
  });
  return f;
}

template <class T>
void rigid_forces(benchmark::State& state, Variant v) {
  const auto n = std::size_t(state.range(0));
  const Scene scene = rigid_bench_scene(n);
  RigidBodySet<T> bodies = make_rigid_bodies<T>(scene);
  CaseJobs jobs(1);
  StepperOptions o;
  o.jobs = jobs.get();
  Stepper<T> stepper(rigid_variant_forces<T>(v, scene, n), rk4, o);
  if (v == Variant::parameters) {
    set_parameters(bodies);
    for (std::size_t i = 0; i < n; ++i) bodies.set_angular_damping(i, T(0.01) * T(i % 4));
  }
  if (v == Variant::applied) {
    bodies.keep_forces(true);
    for (std::size_t i = 0; i < n; ++i) {
      bodies.apply_force(i, {T(0.5), T(i % 3), T(-0.25)});
      bodies.apply_torque(i, {T(0.1), T(-0.2), T(i % 2)});
    }
  }
  stepper.advance(bodies, T(kDt), kSteps);
  for (auto _ : state) {
    stepper.advance(bodies, T(kDt), kSteps);
    benchmark::ClobberMemory();
  }
  if (!all_finite(bodies)) state.SkipWithError("state is not finite after the run");
  report_body_steps(state, double(n) * double(kSteps), 30.0 * sizeof(T));
}

void register_all() {
  const std::string isa(isa_name(best_isa()));
  for (Variant v : {Variant::fused, Variant::applied, Variant::parameters, Variant::callback, Variant::callback_divide,
                    Variant::callback_empty, Variant::staged, Variant::springs}) {
    const std::string name = std::string("game/") + variant_name(v) + "/rk4/float/" + isa;
    benchmark::RegisterBenchmark(name.c_str(), particle_forces<float>, v)
        ->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
  }
  for (Variant v : {Variant::fused, Variant::applied, Variant::parameters, Variant::callback, Variant::springs}) {
    const std::string name = std::string("game/rigid-") + variant_name(v) + "/rk4/float/" + isa;
    benchmark::RegisterBenchmark(name.c_str(), rigid_forces<float>, v)
        ->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
