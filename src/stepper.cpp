#include "kinema/stepper.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>

#include "kernels/kernels.hpp"
#include "kinema/error.hpp"

namespace kinema {
namespace {

// A force parameter (or a sum of them) in the stepper's precision. Values valid in double
// can overflow float: refuse them here rather than let inf times a zero inverse mass make
// NaN out of a kinematic body.
template <class T>
std::string type_name() {
  return sizeof(T) == 4 ? "float" : "double";
}

// The shortest text that reads back as the same value (no "0.000000" for 1e-50).
template <class T>
std::string shortest(T x) {
  char text[32];
  std::snprintf(text, sizeof text, sizeof(T) == 4 ? "%.9g" : "%.17g", double(x));
  return text;
}

template <class T>
T narrow(double x) {
  const T out = T(x);
  if (!std::isfinite(out)) {
    throw Error("force parameters overflow " + type_name<T>() +
                " (their sum, per kind of term, must be finite in the stepper's precision)");
  }
  return out;
}

template <class T>
kernels::LocalForces<T> resolve(std::span<const LocalTerm> terms) {
  Vec3<double> g{}, weighted_anchor{}, point_force_sum{};
  double spring_k = 0, linear = 0, quadratic = 0;
  kernels::LocalForces<T> out;
  for (const LocalTerm& term : terms) {
    if (auto* t = std::get_if<Gravity>(&term)) {
      for (int d = 0; d < 3; ++d) g[d] += t->g[d];
    } else if (auto* t = std::get_if<LinearDrag>(&term)) {
      linear += t->k;
    } else if (auto* t = std::get_if<QuadraticDrag>(&term)) {
      quadratic += t->k;
    } else if (auto* t = std::get_if<Spring>(&term)) {
      // Springs sum to one: -sum k_i (x - a_i) = -K (x - sum k_i a_i / K).
      spring_k += t->k;
      linear += t->damping;
      for (int d = 0; d < 3; ++d) weighted_anchor[d] += t->k * t->anchor[d];
    } else if (auto* t = std::get_if<Central>(&term)) {
      const int c = out.central_count++;
      for (int d = 0; d < 3; ++d) out.center[c][d] = narrow<T>(t->center[d]);
      out.mu[c] = narrow<T>(t->mu);
    } else if (auto* t = std::get_if<PointForce>(&term)) {
      for (int d = 0; d < 3; ++d) point_force_sum[d] += t->force[d];
    }
  }
  for (int d = 0; d < 3; ++d) {
    out.gravity[d] = narrow<T>(g[d]);
    out.constant_force[d] = narrow<T>(point_force_sum[d]);
    out.anchor[d] = spring_k > 0 ? narrow<T>(weighted_anchor[d] / spring_k) : T(0);
  }
  out.spring_k = narrow<T>(spring_k);
  out.linear = narrow<T>(linear);
  out.quadratic = narrow<T>(quadratic);
  return out;
}

// The rotational terms; rigid bodies only.
template <class T>
kernels::RotationalForces<T> resolve_rotational(std::span<const LocalTerm> terms) {
  Vec3<double> torque{};
  double drag = 0;
  kernels::RotationalForces<T> out;
  for (const LocalTerm& term : terms) {
    if (auto* t = std::get_if<Torque>(&term)) {
      for (int d = 0; d < 3; ++d) torque[d] += t->torque[d];
    } else if (auto* t = std::get_if<AngularDrag>(&term)) {
      drag += t->c;
    } else if (auto* t = std::get_if<PointForce>(&term)) {
      const int p = out.point_count++;
      for (int d = 0; d < 3; ++d) {
        out.point[p][d] = narrow<T>(t->point[d]);
        out.force[p][d] = narrow<T>(t->force[d]);
      }
    }
  }
  for (int d = 0; d < 3; ++d) out.torque[d] = narrow<T>(torque[d]);
  out.angular_drag = narrow<T>(drag);
  return out;
}

template <class T>
kernels::BodyArrays<T> arrays(ParticleSet<T>& b) {
  return {{b.px(), b.py(), b.pz()}, {b.vx(), b.vy(), b.vz()}, b.inv_mass()};
}

// One unit of the staged path, run per block. Phases that read other blocks' state
// (coupled forces) need a barrier before them; without coupled terms a block runs all
// phases of a step in one go while its data is in cache.
enum class PhaseKind { stage, coupled, finish, kick, drift };
struct Phase {
  PhaseKind kind;
  int index;  // stage or operation
};
constexpr int kMaxPhases = 3 * kMaxStages + 1;

template <class F>
void range_trampoline(std::size_t begin, std::size_t end, unsigned, void* context) {
  (*static_cast<F*>(context))(begin, end);
}

}  // namespace

template <class T>
struct Stepper<T>::Impl {
  ForceModel<T> forces;
  Method method;
  StepperOptions options;
  std::unique_ptr<TbbJobSystem> owned_jobs;
  JobSystem* jobs = nullptr;
  const kernels::KernelTable<T>* table = nullptr;
  kernels::LocalForces<T> local;
  kernels::StageFn<T> stage_fn = nullptr;
  kernels::FusedFn<T> fused_fn = nullptr;
  kernels::RigidFn<T> rigid_fn = nullptr;
  kernels::LocalForces<T> rigid_local;
  kernels::RotationalForces<T> rotational;

  double origin = 0;
  std::uint64_t steps_since_origin = 0;
  T last_h = 0;

  std::array<Phase, kMaxPhases> phases{};
  int phase_count = 0;
  std::size_t capacity = 0;
  // Staged scratch: stage positions and velocities (stage 0 is the bodies themselves),
  // stage accelerations, and the force accumulator of callback and coupled terms.
  std::array<std::array<AlignedArray<T>, 3>, kMaxStages> stage_x, stage_v, stage_a;
  std::array<AlignedArray<T>, 3> force;

  // Per-step context the phases read.
  ParticleSet<T>* bodies = nullptr;
  T h = 0;
  double t0 = 0;

  Impl(ForceModel<T> f, const Method& m, StepperOptions o)
      : forces(std::move(f)), method(m), options(o) {
    validate(method);
    table = &kernels::kernel_table<T>(options.isa, options.relaxed_fma);
    if (options.jobs == nullptr) {
      owned_jobs = std::make_unique<TbbJobSystem>(options.threads);
      jobs = owned_jobs.get();
    } else {
      jobs = options.jobs;
    }
    local = resolve<T>(forces.local_terms());
    // Particles have no orientation: the point forces' push is for rigid bodies only.
    rigid_local = local;
    local.constant_force = {};
    rotational = resolve_rotational<T>(forces.local_terms());
    const int quad = local.has_quadratic(), central = local.has_central();
    stage_fn = table->stage[quad][central];
    const int builtin = builtin_index(method);
    if (builtin >= 0 && forces.fusable()) rigid_fn = table->rigid[builtin][quad][central];
    if (builtin >= 0 && forces.fusable() && !options.force_staged) {
      fused_fn = table->fused[builtin][quad][central];
    } else {
      plan_phases();
    }
  }

  bool coupled() const { return !forces.coupled_terms().empty(); }
  bool needs_force_scratch() const { return coupled() || !forces.callbacks().empty(); }

  void plan_phases() {
    auto push = [&](PhaseKind k, int i) { phases[phase_count++] = {k, i}; };
    if (method.kind == MethodKind::runge_kutta) {
      for (int s = 0; s < method.tableau.stages; ++s) {
        push(PhaseKind::stage, s);
        if (coupled()) push(PhaseKind::coupled, s);
      }
      push(PhaseKind::finish, 0);
      return;
    }
    for (int k = 0; k < method.scheme.count; ++k) {
      if (method.scheme.ops[k].kind == OpKind::drift) {
        push(PhaseKind::drift, k);
        continue;
      }
      push(PhaseKind::stage, k);
      if (coupled()) push(PhaseKind::coupled, k);
      push(PhaseKind::kick, k);
    }
  }

  void reserve(std::size_t n) {
    n = padded_count<T>(n);
    if (fused_fn != nullptr || n <= capacity) return;
    const int stages = method.kind == MethodKind::runge_kutta ? method.tableau.stages : 1;
    for (int s = 0; s < stages; ++s) {
      for (int d = 0; d < 3; ++d) {
        if (s > 0) stage_x[s][d].resize(n), stage_v[s][d].resize(n);
        stage_a[s][d].resize(n);
      }
    }
    if (needs_force_scratch()) {
      for (auto& f : force) f.resize(n);
    }
    capacity = n;
  }

  // Runs fn(body_begin, body_end) over every block, on the job system when worth it.
  template <class F>
  void for_blocks(std::size_t bodies_count, F&& fn) {
    const std::size_t blocks = (bodies_count + kBlockBodies - 1) / kBlockBodies;
    auto over_blocks = [&](std::size_t b0, std::size_t b1) {
      fn(b0 * kBlockBodies, std::min(b1 * kBlockBodies, bodies_count));
    };
    if (bodies_count < options.inline_below || jobs->worker_count() <= 1 || blocks <= 1) {
      over_blocks(0, blocks);
      return;
    }
    using Fn = decltype(over_blocks);
    jobs->wait(jobs->enqueue(&range_trampoline<Fn>, blocks, 1, &over_blocks));
  }

  double time() const { return origin + double(steps_since_origin) * double(last_h); }

  void check_step_size(T step_size) const {
    if (!(std::isfinite(step_size) && step_size > 0)) {
      throw Error("step size h must be positive and finite in " + type_name<T>() + ", got " +
                  shortest(step_size));
    }
    check_scaled_forces(step_size);
  }

  void start_steps(ParticleSet<T>& b, T step_size) {
    check_step_size(step_size);
    if (step_size != last_h) {
      h = step_size;
      origin = time();
      steps_since_origin = 0;
      last_h = step_size;
    }
    bodies = &b;
    h = step_size;
  }

  // Runge-Kutta kernels multiply the force parameters by sigma h (accel_scale): with a large
  // step, parameters near the type's limit would overflow there.
  void check_scaled_forces(T step_size) const {
    const T scale = accel_scale(step_size);
    bool finite = std::isfinite(local.spring_k * scale) && std::isfinite(local.linear * scale) &&
                  std::isfinite(local.quadratic * scale);
    for (int d = 0; d < 3; ++d) {
      finite = finite && std::isfinite(local.gravity[d] * scale) &&
               std::isfinite(local.constant_force[d] * scale);
    }
    for (int c = 0; c < local.central_count; ++c) finite = finite && std::isfinite(local.mu[c] * scale);
    if (!finite) {
      throw Error("step size h = " + shortest(step_size) +
                  " times the force parameters overflows " + type_name<T>() + "; take a smaller step");
    }
  }

  void advance(RigidBodySet<T>& b, T step_size, std::uint64_t steps) {
    if (rigid_fn == nullptr) {
      throw Error("rigid bodies need a built-in method and local force terms only (no "
                  "callbacks, no coupled terms)");
    }
    start_steps(b.centers_, step_size);
    kernels::RigidJob<T> job{arrays(b.centers_), {b.q(0), b.q(1), b.q(2), b.q(3)},
                             {b.l(0), b.l(1), b.l(2)},
                             {b.inv_inertia(0), b.inv_inertia(1), b.inv_inertia(2)},
                             rigid_local, rotational, h, options.renormalize_quaternions};
    for_blocks(b.padded_size(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; i += kBlockBodies) {
        const std::size_t block_end = std::min(i + kBlockBodies, end);
        for (std::uint64_t k = 0; k < steps; ++k) rigid_fn(job, i, block_end);
      }
    });
    steps_since_origin += steps;
  }

  void advance(ParticleSet<T>& b, T step_size, std::uint64_t steps) {
    start_steps(b, step_size);
    const std::size_t n = b.padded_size();
    if (fused_fn != nullptr) {
      // Local, time-independent forces: each block can take all its steps while it sits in
      // cache. Every body sees the same operations as step by step, so the bits agree.
      const kernels::FusedJob<T> job{arrays(b), local, h};
      for_blocks(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; i += kBlockBodies) {
          const std::size_t block_end = std::min(i + kBlockBodies, end);
          for (std::uint64_t k = 0; k < steps; ++k) fused_fn(job, i, block_end);
        }
      });
      steps_since_origin += steps;
      return;
    }
    reserve(n);
    for (std::uint64_t k = 0; k < steps; ++k) {
      t0 = time();
      step_staged(n);
      ++steps_since_origin;
    }
  }

  void step_staged(std::size_t n) {
    if (coupled()) {
      for (int p = 0; p < phase_count; ++p) {
        for_blocks(n, [&](std::size_t begin, std::size_t end) {
          for (std::size_t i = begin; i < end; i += kBlockBodies) {
            run_phase(phases[p], i, std::min(i + kBlockBodies, end));
          }
        });
      }
      return;
    }
    for_blocks(n, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; i += kBlockBodies) {
        for (int p = 0; p < phase_count; ++p) {
          run_phase(phases[p], i, std::min(i + kBlockBodies, end));
        }
      }
    });
  }

  // Stage s's state is the bodies' own for stage 0, for a stage whose tableau row is all
  // zero (nothing to add), and for every kick-drift stage; else its stage buffers.
  bool own_state(int s) const {
    if (s == 0 || method.kind == MethodKind::kick_drift) return true;
    for (int j = 0; j < s; ++j) {
      if (method.tableau.a[s][j] != 0) return false;
    }
    return true;
  }
  const T* state_x(int s, int d) {
    return own_state(s) ? arrays(*bodies).x[d] : stage_x[s][d].data();
  }
  const T* state_v(int s, int d) {
    return own_state(s) ? arrays(*bodies).v[d] : stage_v[s][d].data();
  }
  // Stage s's velocities (the x derivative) and accelerations, as three component arrays.
  std::array<const T*, 3> velocities(int s) {
    return {state_v(s, 0), state_v(s, 1), state_v(s, 2)};
  }
  std::array<const T*, 3> accelerations(int s) {
    return {stage_a[s][0].data(), stage_a[s][1].data(), stage_a[s][2].data()};
  }

  int accel_slot(const Phase& p) const {
    return method.kind == MethodKind::runge_kutta ? p.index : 0;
  }
  double phase_time(const Phase& p) const {
    const double c = method.kind == MethodKind::runge_kutta ? method.tableau.c[p.index]
                                                            : method.scheme.ops[p.index].time;
    return t0 + c * double(h);
  }

  void run_phase(const Phase& p, std::size_t begin, std::size_t end) {
    switch (p.kind) {
      case PhaseKind::stage: return run_stage(p, begin, end);
      case PhaseKind::coupled: return run_coupled(p, begin, end);
      case PhaseKind::finish: return run_finish(begin, end);
      case PhaseKind::kick:
      case PhaseKind::drift: return run_kick_drift(p, begin, end);
    }
  }

  void run_stage(const Phase& p, std::size_t begin, std::size_t end) {
    const int s = accel_slot(p);
    kernels::StageJob<T> job{};
    job.accel_scale = accel_scale();
    job.inv_mass = bodies->inv_mass();
    job.forces = local;
    auto body = arrays(*bodies);
    for (int d = 0; d < 3; ++d) {
      job.x.in[d] = body.x[d];
      job.v.in[d] = body.v[d];
      job.x.out[d] = s > 0 ? stage_x[s][d].data() : nullptr;
      job.v.out[d] = s > 0 ? stage_v[s][d].data() : nullptr;
      job.acc[d] = stage_a[s][d].data();
    }
    double first = 0;
    for (int j = 0; j < s; ++j) {
      const double a = method.tableau.a[s][j];
      if (a == 0) continue;
      if (first == 0) first = a;
      job.x.add(a, first, velocities(j));
      job.v.add(a, first, accelerations(j));
    }
    set_steps(job.x, job.v, first);
    stage_fn(job, begin, end);
    if (!needs_force_scratch()) return;
    for (auto& f : force) std::fill(f.data() + begin, f.data() + end, T(0));
    const ParticleBlock<T> block = block_view(s, begin, end, phase_time(p));
    for (const auto& callback : forces.callbacks()) callback(block);
    if (!coupled()) add_forces(s, begin, end);
  }

  // What the stage accelerations are multiplied by: sigma h for Runge-Kutta methods (see
  // kernels::acceleration_scale), 1 for kicks, which scale by their own weight.
  T accel_scale(T step_size) const {
    if (method.kind != MethodKind::runge_kutta) return 1;
    return T(kernels::acceleration_scale(method.tableau)) * step_size;
  }
  T accel_scale() const { return accel_scale(h); }

  // The step of a position and a velocity combination whose first weight is w.
  void set_steps(kernels::Combination<T>& x, kernels::Combination<T>& v, double w) const {
    x.step = T(w) * h;
    v.step = T(w / kernels::acceleration_scale(method.tableau));
  }

  ParticleBlock<T> block_view(int s, std::size_t begin, std::size_t end, double t) {
    ParticleBlock<T> b;
    b.begin = begin;
    b.count = end - begin;
    b.t = t;
    b.px = state_x(s, 0) + begin, b.py = state_x(s, 1) + begin, b.pz = state_x(s, 2) + begin;
    b.vx = state_v(s, 0) + begin, b.vy = state_v(s, 1) + begin, b.vz = state_v(s, 2) + begin;
    b.inv_mass = bodies->inv_mass() + begin;
    b.fx = force[0].data() + begin, b.fy = force[1].data() + begin, b.fz = force[2].data() + begin;
    return b;
  }

  void add_forces(int s, std::size_t begin, std::size_t end) {
    kernels::ForceJob<T> job{};
    for (int d = 0; d < 3; ++d) job.acc[d] = stage_a[s][d].data(), job.force[d] = force[d].data();
    job.inv_mass = bodies->inv_mass();
    job.scale = accel_scale();
    table->add_forces(job, begin, end);
  }

  void run_coupled(const Phase& p, std::size_t begin, std::size_t end) {
    const int s = accel_slot(p);
    const ParticleState<T> all{bodies->padded_size(), state_x(s, 0), state_x(s, 1), state_x(s, 2),
                               state_v(s, 0), state_v(s, 1), state_v(s, 2), bodies->inv_mass()};
    const ParticleBlock<T> block = block_view(s, begin, end, phase_time(p));
    for (const auto& term : forces.coupled_terms()) term->accumulate(all, block);
    add_forces(s, begin, end);
  }

  void run_finish(std::size_t begin, std::size_t end) {
    auto body = arrays(*bodies);
    kernels::CombineJob<T> x{}, v{};
    for (int d = 0; d < 3; ++d) {
      x.c.in[d] = x.c.out[d] = body.x[d];
      v.c.in[d] = v.c.out[d] = body.v[d];
    }
    double first = 0;
    for (int s = 0; s < method.tableau.stages; ++s) {
      const double b = method.tableau.b[s];
      if (b == 0) continue;
      if (first == 0) first = b;
      x.c.add(b, first, velocities(s));
      v.c.add(b, first, accelerations(s));
    }
    set_steps(x.c, v.c, first);
    // Positions first: they read the stage-0 velocities, which are the bodies' own.
    table->combine(x, begin, end);
    table->combine(v, begin, end);
  }

  void run_kick_drift(const Phase& p, std::size_t begin, std::size_t end) {
    auto body = arrays(*bodies);
    const bool kick = p.kind == PhaseKind::kick;
    kernels::CombineJob<T> job{};
    for (int d = 0; d < 3; ++d) job.c.in[d] = job.c.out[d] = kick ? body.v[d] : body.x[d];
    job.c.add(1, 1, kick ? accelerations(0) : velocities(0));
    job.c.step = T(method.scheme.ops[p.index].weight) * h;
    table->combine(job, begin, end);
  }
};

template <class T>
Stepper<T>::Stepper(ForceModel<T> forces, const Method& method, StepperOptions options)
    : impl_(std::make_unique<Impl>(std::move(forces), method, options)) {}

template <class T>
Stepper<T>::~Stepper() = default;
template <class T>
Stepper<T>::Stepper(Stepper&&) noexcept = default;
template <class T>
Stepper<T>& Stepper<T>::operator=(Stepper&&) noexcept = default;

template <class T>
void Stepper<T>::step(ParticleSet<T>& io_bodies, T h) {
  impl_->advance(io_bodies, h, 1);
}

template <class T>
void Stepper<T>::advance(ParticleSet<T>& io_bodies, T h, std::uint64_t steps) {
  impl_->advance(io_bodies, h, steps);
}

template <class T>
void Stepper<T>::step(RigidBodySet<T>& io_bodies, T h) {
  impl_->advance(io_bodies, h, 1);
}

template <class T>
void Stepper<T>::advance(RigidBodySet<T>& io_bodies, T h, std::uint64_t steps) {
  impl_->advance(io_bodies, h, steps);
}

template <class T>
void Stepper<T>::check_step_size(T h) const {
  impl_->check_step_size(h);
}

template <class T>
void Stepper<T>::reserve(std::size_t bodies) {
  impl_->reserve(bodies);
}

template <class T>
double Stepper<T>::time() const {
  return impl_->time();
}

template <class T>
void Stepper<T>::set_time(double t) {
  if (!std::isfinite(t)) throw Error("time must be finite");
  impl_->origin = t;
  impl_->steps_since_origin = 0;
}

template <class T>
const Method& Stepper<T>::method() const {
  return impl_->method;
}
template <class T>
const ForceModel<T>& Stepper<T>::forces() const {
  return impl_->forces;
}
template <class T>
Isa Stepper<T>::isa() const {
  return impl_->table->isa;
}
template <class T>
bool Stepper<T>::fused() const {
  return impl_->fused_fn != nullptr;
}
template <class T>
unsigned Stepper<T>::threads() const {
  return impl_->jobs->worker_count();
}

template class Stepper<float>;
template class Stepper<double>;

}  // namespace kinema
