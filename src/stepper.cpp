// The Stepper facade: it picks the path once, keeps the clock and what lives across calls,
// and builds a StepContext for each call. Force lowering, block iteration and the staged
// path live in their own files.
#include "kinema/stepper.hpp"

#include <bit>
#include <cmath>
#include <memory>
#include <string>

#include "blocks.hpp"
#include "error_control.hpp"
#include "finite_guard.hpp"
#include "force_lowering.hpp"
#include "kernels/kernels.hpp"
#include "kinema/error.hpp"
#include "kinema/stability.hpp"
#include "staged_path.hpp"
#include "step_context.hpp"
#include "worker_tuner.hpp"

namespace kinema {
namespace {

// Simulated time as origin + steps x h: no running sum, so step k sees exactly t0 + k h.
template <class T>
struct Clock {
  double origin = 0;
  std::uint64_t steps = 0;
  T h = 0;

  double time() const { return origin + double(steps) * double(h); }
  // A new step size moves the origin to now.
  void use(T step_size) {
    if (step_size == h) return;
    origin = time();
    steps = 0;
    h = step_size;
  }
  void set(double t) { origin = t, steps = 0; }
};

}  // namespace

template <class T>
struct Stepper<T>::Impl {
  std::shared_ptr<const ForceModel<T>> forces;
  Method method;
  StepperOptions options;
  JobSystem* jobs = nullptr;
  const kernels::KernelTable<T>* table = nullptr;
  std::unique_ptr<LoweredForces<T>> lowered;  // a fixed address: the staged path keeps references
  kernels::FusedFn<T> fused_fn = nullptr;
  kernels::RigidFn<T> rigid_fn = nullptr;
  std::unique_ptr<StagedPath<T>> staged;  // when the fused path does not apply
  std::unique_ptr<StagedPath<T>> probe;   // evaluates accelerations alone (made on demand)
  Clock<T> clock;
  Checkpoint<T> checkpoint;  // the finiteness guard's copy of the state
  WorkerTuners tuners;       // worker counts measured per kind and size of call
  WorkerTuner* last_tuner = nullptr;  // of the last call measured (for prepare)
  unsigned favoured_workers = 0;

  Impl(std::shared_ptr<const ForceModel<T>> f, const Method& m, StepperOptions o)
      : method(m), options(o) {
    validate(method);
    check_guard(options);
    table = &kernels::kernel_table<T>(options.isa, options.relaxed_fma);
    jobs = options.jobs != nullptr ? options.jobs : &default_job_system(options.threads);
    use(std::move(f));
  }

  // The kernels a model takes: its fused kernels, or a staged path built on `l`.
  struct Paths {
    kernels::FusedFn<T> fused = nullptr;
    kernels::RigidFn<T> rigid = nullptr;
    std::unique_ptr<StagedPath<T>> staged;
  };

  // Builds everything the model needs first (lowering, kernels, scratch as large as the last):
  // whatever throws, bad parameters or no memory, leaves the stepper as it was.
  void use(std::shared_ptr<const ForceModel<T>> f) {
    if (!f) throw Error("stepper: null force model");
    auto fresh = std::make_unique<LoweredForces<T>>(lower_forces<T>(f->local_terms()));
    fresh->coupled = lower_coupled<T>(*f);
    Paths paths = pick_kernels(*f, *fresh);
    if (paths.staged) paths.staged->reserve(staged ? staged->capacity() : 0);
    probe.reset();  // it refers to the lowering being replaced
    forces = std::move(f);
    lowered = std::move(fresh);
    fused_fn = paths.fused, rigid_fn = paths.rigid;
    staged = std::move(paths.staged);
  }

  Paths pick_kernels(const ForceModel<T>& f, const LoweredForces<T>& l) const {
    Paths paths;
    const int quad = l.particle.has_quadratic(), central = l.particle.has_central();
    const int builtin = builtin_index(method);
    if (builtin >= 0 && f.fusable()) paths.rigid = table->rigid[builtin][quad][central];
    if (builtin >= 0 && f.fusable() && !options.force_staged) {
      paths.fused = table->fused[builtin][quad][central];
    } else {
      paths.staged = std::make_unique<StagedPath<T>>(f, method, *table, l.particle, l.coupled);
    }
    return paths;
  }

  // What the stage accelerations are multiplied by: sigma h for Runge-Kutta methods (see
  // kernels::acceleration_scale), 1 for kicks, which scale by their own weight.
  T accel_scale(T step_size) const {
    if (method.kind != MethodKind::runge_kutta) return 1;
    return T(kernels::acceleration_scale(method.tableau)) * step_size;
  }

  // What a step of the given set would throw: `forces` are the particles' or the rigid
  // bodies' (which add the point forces' push).
  void check_step_size(T step_size, const kernels::LocalForces<T>& forces) const {
    if (!(std::isfinite(step_size) && step_size > 0)) {
      throw Error("step size h must be positive and finite in " + type_name<T>() + ", got " +
                  shortest_text(step_size));
    }
    check_scaled_forces(forces, accel_scale(step_size), step_size);
    const auto& nbody = lowered->coupled.nbody;
    if (nbody && !std::isfinite(accel_scale(step_size) * T(nbody->G))) {
      throw Error("step size h = " + shortest_text(step_size) + " times nbody.G overflows " +
                  type_name<T>() + "; take a smaller step");
    }
  }

  // Springs must not reach past the set.
  void check_reach(const ParticleSet<T>& b) const {
    const std::size_t covered = lowered->coupled.springs.covered;
    if (covered > b.size()) {
      throw Error("springs: a pair joins body " + std::to_string(covered - 1) + ", but the set has " +
                  std::to_string(b.size()) + " bodies");
    }
  }

  StepContext<T> start(ParticleSet<T>& bodies, T step_size, const kernels::LocalForces<T>& forces,
                       const Workers& workers) {
    check_step_size(step_size, forces);
    clock.use(step_size);
    return {bodies, step_size, accel_scale(step_size), 0, workers};
  }

  // Kinds of call that cost differently per body-step: each has its own measurements.
  enum class CallKind : std::uint64_t { fused, staged, rigid, adaptive, accelerations };

  // Runs fn(workers) on the workers chosen for this kind and size of call, and times it: fn
  // returns the body-steps it did. A call that throws is not counted.
  template <class Fn>
  void timed(CallKind kind, std::size_t bodies, std::uint64_t steps, Fn&& fn) {
    if (bodies < options.inline_below || block_count(bodies) <= 1) return void(fn(Workers{jobs, 0}));
    if (options.workers == WorkerChoice::all) return void(fn(all_workers(*jobs)));
    const std::uint64_t key = std::uint64_t(kind) << 8 | std::uint64_t(std::bit_width(bodies)) << 1 | (steps > 1);
    WorkerTuner& tuner = tuners.find(key, jobs->worker_count());
    last_tuner = &tuner;
    const Workers workers{jobs, tuner.choose()};
    const std::uint64_t begin = tuner_ticks();
    const double work = fn(workers);
    tuner.record(workers.count, tuner_ticks() - begin, work);
    favoured_workers = tuner.best();
  }

  CallKind kind_of(const ParticleSet<T>&) const { return fused_fn ? CallKind::fused : CallKind::staged; }
  CallKind kind_of(const RigidBodySet<T>&) const { return CallKind::rigid; }

  // Speed limits the clamp can hold in T.
  static void check_guard(const StepperOptions& o) {
    if (o.guard != FiniteGuard::clamp) return;
    for (const auto& [name, value] : {std::pair{"max_speed", o.max_speed},
                                      std::pair{"max_angular_speed", o.max_angular_speed}}) {
      // Its square too: the clamp compares squared speeds.
      if (!(value > 0 && std::isfinite(T(value) * T(value)))) {
        throw Error(std::string("stepper options: ") + name + " must be > 0 and finite in " +
                    type_name<T>() + ", got " + shortest_text(value));
      }
    }
  }

  // What the finiteness guard does inside a call: save each block before its steps, clamp
  // after every step, scan each block after its last (on the fused path while the block is
  // still in cache).
  struct Guard {
    const StateArrays<T>& state;
    Checkpoint<T>& checkpoint;
    FiniteScan<T> scan;
    bool clamp;
  };

  template <class Set>
  void advance(Set& b, T step_size, std::uint64_t steps) {
    timed(kind_of(b), b.size(), steps, [&](const Workers& w) {
      advance(w, b, step_size, steps);
      return double(b.size()) * double(steps);
    });
  }

  template <class Set>
  void advance(const Workers& w, Set& b, T step_size, std::uint64_t steps) {
    if (options.guard == FiniteGuard::off) return run(w, b, step_size, steps, nullptr);
    const StateArrays<T> state = state_arrays(b);
    checkpoint.reserve(state);
    if (!guarded_run(w, b, step_size, steps, state)) return;
    // Back to the start, then step by step to the step that made the value.
    checkpoint.restore(w, state);
    clock.steps -= steps;
    for (std::uint64_t k = 1; k <= steps; ++k) {
      if (const auto bad = guarded_run(w, b, step_size, 1, state)) {
        checkpoint.restore(w, state);
        --clock.steps;
        throw NonFiniteError(k, clock.time(), bad->body, bad->field);
      }
    }
  }

  template <class Set>
  std::optional<NonFinite> guarded_run(const Workers& w, Set& b, T step_size, std::uint64_t steps,
                                       const StateArrays<T>& state) {
    Guard guard{state, checkpoint, FiniteScan<T>(state), options.guard == FiniteGuard::clamp};
    run(w, b, step_size, steps, &guard);
    return guard.scan.found();
  }

  void clamp(ParticleSet<T>& b, Block block) const { clamp_speeds(b, block, options.max_speed); }
  void clamp(RigidBodySet<T>& b, Block block) const {
    clamp_speeds(b, block, options.max_speed, options.max_angular_speed);
  }

  // A block's steps with the guard's work around them. Each body's steps are the same
  // operations whether its block takes them in one go or one at a time.
  template <class Set, class Step>
  void run_block(Set& b, Block block, std::uint64_t steps, Guard* guard, Step&& step) {
    if (guard) guard->checkpoint.save(guard->state, block);
    for (std::uint64_t k = 0; k < steps; ++k) {
      step(block);
      if (guard && guard->clamp) clamp(b, block);
    }
    if (guard) guard->scan.scan(block);
  }

  void run(const Workers& w, RigidBodySet<T>& b, T step_size, std::uint64_t steps, Guard* guard) {
    if (rigid_fn == nullptr) {
      throw Error("rigid bodies need a built-in method and local force terms only (no "
                  "callbacks, no coupled terms)");
    }
    const StepContext<T> c = start(b.centers_, step_size, lowered->rigid, w);
    const kernels::RigidJob<T> job{arrays(b.centers_), {b.q(0), b.q(1), b.q(2), b.q(3)},
                                   {b.l(0), b.l(1), b.l(2)},
                                   {b.inv_inertia(0), b.inv_inertia(1), b.inv_inertia(2)},
                                   lowered->rigid, lowered->rotation, c.h,
                                   options.renormalize_quaternions};
    for_each_block(w, b.centers_.padded_size(), [&](Block block) {
      run_block(b, block, steps, guard, [&](Block k) { rigid_fn(job, k.begin, k.end); });
    });
    clock.steps += steps;
  }

  void run(const Workers& w, ParticleSet<T>& b, T step_size, std::uint64_t steps, Guard* guard) {
    check_reach(b);
    StepContext<T> c = start(b, step_size, lowered->particle, w);
    if (fused_fn == nullptr) return run_staged(c, steps, guard);
    // Local, time-independent forces: each block can take all its steps while it sits in
    // cache. Every body sees the same operations as step by step, so the bits agree.
    const kernels::FusedJob<T> job{arrays(b), lowered->particle, c.h};
    for_each_block(w, b.padded_size(), [&](Block block) {
      run_block(b, block, steps, guard, [&](Block k) { fused_fn(job, k.begin, k.end); });
    });
    clock.steps += steps;
  }

  AdaptiveStats advance_to(ParticleSet<T>& b, double t_end, const Tolerances& tol) {
    check_adaptive(t_end, tol);
    check_reach(b);
    AdaptiveStats stats;
    timed(CallKind::adaptive, b.size(), 2, [&](const Workers& w) {
      stats = advance_to(w, b, t_end, tol);
      return double(b.size()) * double(stats.evaluations);
    });
    return stats;
  }

  AdaptiveStats advance_to(const Workers& w, ParticleSet<T>& b, double t_end, const Tolerances& tol) {
    staged->reserve(b.padded_size());
    AdaptiveStats stats;
    double t = clock.time();
    if (t_end == t) return stats;
    StepController controller(std::min(method.order, method.embedded_order));
    double max_step = tol.max_step;
    if (tol.limit_to_stable_step) {
      const StiffnessEstimate e = estimate_stiffness(b, *forces, t, 40, options);
      const double stable = largest_stable_step(method, e);
      if (stable > 0) max_step = std::min(max_step, stable);
    }
    T kept_scale = 0;  // the acceleration scale stage 0's kept accelerations carry; 0: none
    double h = tol.initial_step > 0 ? tol.initial_step : first_step(w, b, t_end - t, tol, kept_scale, stats);
    while (t < t_end) {
      h = std::min(h, max_step);
      // No sliver of a last step: one within 1% of the end takes it, if max_step allows.
      const bool last = t + 1.01 * h >= t_end && t_end - t <= max_step;
      const T size = T(last ? t_end - t : h);
      if (!(size > 0) || t + double(size) == t) {
        throw Error("advance_to: the step size underflows at t = " + shortest_text(t) +
                    "; the tolerances cannot be met in " + type_name<T>());
      }
      StepContext<T> c = start(b, size, lowered->particle, w);
      c.t0 = clock.time();
      const typename StagedPath<T>::Attempt attempt{tol.rtol, tol.atol, kept_scale > 0 ? c.accel_scale / kept_scale : T(0)};
      const double err = staged->attempt(c, attempt);
      stats.evaluations += std::uint64_t(method.tableau.stages - (kept_scale > 0 ? 1 : 0));
      const bool accepted = err <= 1;
      if (accepted) {
        ++clock.steps;
        if (last) clock.set(t_end);
        t = clock.time();
        ++stats.accepted;
        stats.smallest_step = stats.accepted == 1 ? double(size) : std::min(stats.smallest_step, double(size));
        stats.largest_step = std::max(stats.largest_step, double(size));
        if (method.tableau.first_same_as_last()) staged->keep_last_stage();
        kept_scale = method.tableau.first_same_as_last() ? c.accel_scale : T(0);
      } else {
        staged->take_back(c);
        ++stats.rejected;
        kept_scale = c.accel_scale;  // stage 0 was evaluated at the state kept
      }
      h = controller.next(double(size), err, accepted);
    }
    stats.next_step = h;
    return stats;
  }

  void accelerations(const ParticleSet<T>& b, double t, T* const out[3]) {
    check_reach(b);
    if (!probe) probe = std::make_unique<StagedPath<T>>(*forces, euler, *table, lowered->particle, lowered->coupled);
    probe->reserve(b.padded_size());
    // Euler's stage 0 carries accelerations times h; with h = 1 they are the accelerations.
    // The stage reads the bodies and writes scratch only.
    timed(CallKind::accelerations, b.size(), 1, [&](const Workers& w) {
      const StepContext<T> c{const_cast<ParticleSet<T>&>(b), T(1), T(1), t, w};
      probe->evaluate_first_stage(c);
      return double(b.size());
    });
    const auto acc = probe->first_stage();
    for (int d = 0; d < 3; ++d) std::copy(acc[d], acc[d] + b.padded_size(), out[d]);
  }

  void check_adaptive(double t_end, const Tolerances& tol) const {
    if (method.embedded_order == 0) {
      throw Error("advance_to needs a method with an embedded pair (bs3, dopri5); " +
                  std::string(method.name) + " has none");
    }
    const auto nonnegative = [](double x) { return std::isfinite(x) && x >= 0; };
    if (!nonnegative(tol.rtol) || !nonnegative(tol.atol) || (tol.rtol == 0 && tol.atol == 0)) {
      throw Error("tolerances: rtol and atol must be finite and >= 0, not both 0; got rtol " +
                  shortest_text(tol.rtol) + ", atol " + shortest_text(tol.atol));
    }
    if (!nonnegative(tol.initial_step) || !(tol.max_step > 0)) {
      throw Error("tolerances: initial_step must be finite and >= 0, max_step > 0");
    }
    if (!std::isfinite(t_end) || t_end < clock.time()) {
      throw Error("advance_to: t_end " + shortest_text(t_end) + " must be finite and not before time() = " +
                  shortest_text(clock.time()));
    }
  }

  // 0.01 |y| / |f(y)| in the error norm's weights (Hairer and Wanner's first guess), from
  // stage 0's accelerations, which the first attempt then reuses.
  double first_step(const Workers& w, ParticleSet<T>& b, double span, const Tolerances& tol, T& kept_scale,
                    AdaptiveStats& stats) {
    const T probe = T(std::min(span, 1.0));
    check_step_size(probe, lowered->particle);
    const StepContext<T> c{b, probe, accel_scale(probe), clock.time(), w};
    staged->evaluate_first_stage(c);
    ++stats.evaluations;
    kept_scale = c.accel_scale;
    const auto acc = staged->first_stage();
    const T* x[3] = {b.px(), b.py(), b.pz()};
    const T* v[3] = {b.vx(), b.vy(), b.vz()};
    double y2 = 0, f2 = 0;
    for (int d = 0; d < 3; ++d) {
      const std::size_t n = b.size();
      y2 += scaled_squares(x[d], x[d], 1, tol.rtol, tol.atol, n) + scaled_squares(v[d], v[d], 1, tol.rtol, tol.atol, n);
      f2 += scaled_squares(v[d], x[d], 1, tol.rtol, tol.atol, n) +
            scaled_squares(acc[d], v[d], 1 / double(c.accel_scale), tol.rtol, tol.atol, n);
    }
    const double components = 6.0 * double(std::max<std::size_t>(b.size(), 1));
    const double d0 = std::sqrt(y2 / components), d1 = std::sqrt(f2 / components);  // RMS, as the norm
    const double h = d0 < 1e-5 || d1 < 1e-5 ? 1e-6 : 0.01 * d0 / d1;
    return std::min(h, span);
  }

  // One pass per stage: the guard's save, clamp and scan are passes of their own.
  void run_staged(StepContext<T>& c, std::uint64_t steps, Guard* guard) {
    staged->reserve(c.bodies.padded_size());
    const std::size_t n = c.bodies.padded_size();
    if (guard) for_each_block(c.workers, n, [&](Block b) { guard->checkpoint.save(guard->state, b); });
    for (std::uint64_t k = 0; k < steps; ++k) {
      c.t0 = clock.time();
      staged->step(c);
      ++clock.steps;
      if (guard && guard->clamp) for_each_block(c.workers, n, [&](Block b) { clamp(c.bodies, b); });
    }
    if (guard) for_each_block(c.workers, n, [&](Block b) { guard->scan.scan(b); });
  }
};

template <class T>
Stepper<T>::Stepper(ForceModel<T> forces, const Method& method, StepperOptions options)
    : Stepper(std::make_shared<const ForceModel<T>>(std::move(forces)), method, options) {}

template <class T>
Stepper<T>::Stepper(std::shared_ptr<const ForceModel<T>> forces, const Method& method,
                    StepperOptions options)
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
AdaptiveStats Stepper<T>::advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances) {
  return impl_->advance_to(io_bodies, t_end, tolerances);
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
  impl_->check_step_size(h, impl_->lowered->particle);
  impl_->check_step_size(h, impl_->lowered->rigid);
}

template <class T>
void Stepper<T>::accelerations(const ParticleSet<T>& bodies, double t, T* const out[3]) {
  impl_->accelerations(bodies, t, out);
}

template <class T>
void Stepper<T>::prepare() {
  const Impl& i = *impl_;
  const bool all = i.options.workers == WorkerChoice::all && i.jobs->worker_count() > 1;
  if (all || (i.last_tuner != nullptr && i.last_tuner->choose() >= 2)) i.jobs->wake();
}

template <class T>
void Stepper<T>::reserve(std::size_t bodies) {
  if (impl_->staged) impl_->staged->reserve(padded_count<T>(bodies));
}

template <class T>
std::size_t Stepper<T>::scratch_bytes() const {
  const Impl& i = *impl_;
  return (i.staged ? i.staged->bytes() : 0) + i.lowered->coupled.springs.bytes() + i.checkpoint.bytes();
}

template <class T>
void Stepper<T>::set_forces(ForceModel<T> forces) {
  impl_->use(std::make_shared<const ForceModel<T>>(std::move(forces)));
}

template <class T>
double Stepper<T>::time() const {
  return impl_->clock.time();
}

template <class T>
void Stepper<T>::set_time(double t) {
  if (!std::isfinite(t)) throw Error("time must be finite");
  impl_->clock.set(t);
}

template <class T>
const Method& Stepper<T>::method() const {
  return impl_->method;
}
template <class T>
const ForceModel<T>& Stepper<T>::forces() const {
  return *impl_->forces;
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

template <class T>
unsigned Stepper<T>::chosen_workers() const {
  return impl_->options.workers == WorkerChoice::all ? impl_->jobs->worker_count() : impl_->favoured_workers;
}

template class Stepper<float>;
template class Stepper<double>;

}  // namespace kinema
