// The Stepper facade: it owns what lives across calls (the core: model, paths, clock), the
// worker choice and the drivers, and hands each call to the driver it belongs to, timed on
// the workers measured fastest for it.
#include "kinema/stepper.hpp"

#include <algorithm>
#include <cmath>
#include <memory>

#include "kinema/error.hpp"
#include "kinema/stability.hpp"
#include "parallel/measured_workers.hpp"
#include "step/adaptive_driver.hpp"
#include "step/fixed_steps.hpp"
#include "step/step_checks.hpp"
#include "step/stepper_access.hpp"
#include "step/stepper_core.hpp"

namespace kinema {

// Kinds of call that cost differently per body-step: each has its own worker timings.
enum class StepperCall : std::uint64_t { fused, staged, rigid, adaptive, accelerations, implicit };

template <class T>
struct Stepper<T>::Impl {
  Impl(std::shared_ptr<const ForceModel<T>> forces, const Method& method, const StepperOptions& options)
      : core(std::move(forces), method, options),
        workers(options.jobs != nullptr ? *options.jobs : default_job_system(options.threads),
                options.workers == WorkerChoice::all, options.inline_below),
        fixed(core) {}

  StepperCall kind_of(const ParticleSet<T>&) const {
    if (core.paths.implicit) return StepperCall::implicit;
    return core.paths.fused ? StepperCall::fused : StepperCall::staged;
  }
  StepperCall kind_of(const RigidBodySet<T>&) const { return StepperCall::rigid; }

  template <class Set>
  void advance(Set& bodies, T h, std::uint64_t steps) {
    fixed.check_step_count(h, steps);  // before anything changes, the continuation too
    continuation.active = false;
    workers.run(std::uint64_t(kind_of(bodies)), bodies.size(), steps, [&](const Workers& w) {
      fixed.advance(w, bodies, h, steps);
      return double(bodies.size()) * double(steps);
    });
    if (steps > 0) forces_used(bodies);
  }

  template <class Set>
  std::uint64_t advance(Set& bodies, T h, std::uint64_t steps, const StopRequest& stop) {
    if (!stop) {
      advance(bodies, h, steps);
      return fixed.events().stop_time() ? fixed.steps_to_stop() : steps;
    }
    fixed.check_step_count(h, steps);
    continuation.active = false;
    const Clock<T> start = core.clock;
    try {
      workers.run(std::uint64_t(kind_of(bodies)), bodies.size(), steps, [&](const Workers& w) {
        fixed.advance(w, bodies, h, steps, &stop);
        return double(bodies.size()) * double(steps);
      });
    } catch (const Stopped&) {
      // Counted from the call's start: a new step size moved the origin there (Clock::use).
      const bool same_count = core.clock.origin == start.origin && core.clock.h == start.h;
      return same_count ? core.clock.steps - start.steps : core.clock.steps;
    }
    if (steps > 0) forces_used(bodies);
    return fixed.events().stop_time() ? fixed.steps_to_stop() : steps;
  }

  // The events an adaptive call watches (none: a null watch); refuses a model they cannot be
  // watched on.
  template <class Set>
  AdaptiveEvents<T> adaptive_events(Set& bodies) {
    AdaptiveEvents<T> events;
    if (const auto call = fixed.watch_adaptive(bodies)) events = {&fixed.events(), *call};
    return events;
  }

  // Applied forces last one call, unless the set keeps them.
  template <class Set>
  static void forces_used(Set& bodies) {
    if (!bodies.keeps_forces()) bodies.clear_forces();
  }

  AdaptiveStats advance_to(ParticleSet<T>& bodies, double t_end, const Tolerances& tolerances, const CallStops& stops) {
    check_adaptive(core.method, t_end, tolerances, core.clock.time());
    const AdaptiveEvents<T> events = adaptive_events(bodies);
    const OrderedHits<T> ordered{fixed.events()};
    core.reach(bodies);
    // A call that goes on from one stopped early keeps its cap (the bodies have moved since)
    // and was checked when it began.
    const bool continues = continuation.continues(t_end, tolerances, bodies);
    if (!continues) check_tolerance_floor(bodies, tolerances);
    AdaptiveStats stats;
    double max_step = continuation.max_step;
    if (!continues) {
      try {
        max_step = step_cap(bodies, t_end, tolerances, stops.interrupt);
      } catch (const Stopped&) {  // nothing taken, nothing kept: the next call starts over
        stats.stopped = true;
        return stats;
      }
    }
    if (!continues) continuation.active = false;  // the driver goes on from an active one
    workers.run(std::uint64_t(StepperCall::adaptive), bodies.size(), 2, [&](const Workers& w) {
      stats = advance_adaptively(core, w, bodies, t_end, tolerances, max_step, continuation, stops, events);
      return double(bodies.size()) * double(stats.evaluations);
    });
    if (stats.accepted > 0 && !stats.stopped) forces_used(bodies);  // they act to the call's end
    if (stats.next_step > 0) proposed_step = stats.next_step;
    return stats;
  }

  AdaptiveStats advance_to(RigidBodySet<T>& bodies, double t_end, const Tolerances& tolerances) {
    check_adaptive(core.method, t_end, tolerances, core.clock.time());
    if (tolerances.limit_to_stable_step) throw Error("advance_to: limit_to_stable_step takes particles only");
    const AdaptiveEvents<T> events = adaptive_events(bodies);
    const OrderedHits<T> ordered{fixed.events()};
    check_tolerance_floor(bodies, tolerances);
    continuation.active = false;
    AdaptiveStats stats;
    workers.run(std::uint64_t(StepperCall::adaptive), bodies.size(), 2, [&](const Workers& w) {
      stats = advance_adaptively(core, w, bodies, t_end, tolerances, events);
      return double(bodies.size()) * double(stats.evaluations);
    });
    if (stats.accepted > 0) forces_used(bodies);
    if (stats.next_step > 0) proposed_step = stats.next_step;
    return stats;
  }

  // The tolerances' max_step, capped at the method's largest stable step for the bodies now
  // when asked to (and when there is a step to take).
  double step_cap(const ParticleSet<T>& bodies, double t_end, const Tolerances& tolerances,
                  const StopRequest* interrupt) {
    const double t = core.clock.time();
    if (!tolerances.limit_to_stable_step || t_end == t) return tolerances.max_step;
    const auto accelerations_now = [&](const ParticleSet<T>& set, T* const out[3]) {
      if (interrupt != nullptr && (*interrupt)()) throw Stopped();
      accelerations(set, t, out, interrupt);
    };
    const double stable = largest_stable_step(core.method, estimate_stiffness<T>(bodies, accelerations_now, 40));
    return stable > 0 ? std::min(tolerances.max_step, stable) : tolerances.max_step;
  }

  // Euler's stage 0 carries accelerations times h; with h = 1 they are the accelerations.
  // The stage reads the bodies and writes scratch only.
  void accelerations(const ParticleSet<T>& bodies, double t, T* const out[3], const StopRequest* stop = nullptr) {
    core.reach(bodies);
    StagedPath<T>& probe = core.acceleration_probe();
    probe.reserve(bodies.padded_size());
    workers.run(std::uint64_t(StepperCall::accelerations), bodies.size(), 1, [&](const Workers& w) {
      const StepContext<T> c{const_cast<ParticleSet<T>&>(bodies), T(1), T(1), t, w, stop};
      probe.evaluate_first_stage(c);
      return double(bodies.size());
    });
    const auto acc = probe.first_stage();
    for (int d = 0; d < 3; ++d) std::copy(acc[d], acc[d] + bodies.padded_size(), out[d]);
  }

  // The rigid path's stage 0 under Euler at the bodies' state: the rates of x, v, q and L.
  void rigid_rates(const RigidBodySet<T>& bodies, double t, T* const out[13]) {
    RigidBlockPath<T>& probe = core.rigid_probe();
    RigidBodySet<T>& set = const_cast<RigidBodySet<T>&>(bodies);  // read: stage 0 writes scratch only
    if (probe.coupled()) core.reach(set.centers());
    probe.reserve(set.padded_size());
    workers.run(std::uint64_t(StepperCall::accelerations), set.size(), 1, [&](const Workers& w) {
      probe.evaluate_rates({set, T(1), core.options.renormalize_quaternions}, w, t);
      return double(set.size());
    });
    for (int c = 0; c < 13; ++c) std::copy(probe.rate_of(c), probe.rate_of(c) + set.padded_size(), out[c]);
  }

  StepperCore<T> core;
  MeasuredWorkers workers;
  FixedSteps<T> fixed;
  double proposed_step = 0;  // the last advance_to's AdaptiveStats::next_step
  AdaptiveContinuation continuation;  // of an advance_to call stopped early
};

template <class T>
AdaptiveContinuation& StepperAccess<T>::continuation(Stepper<T>& s) {
  return s.impl_->continuation;
}

template <class T>
const AdaptiveContinuation& StepperAccess<T>::continuation(const Stepper<T>& s) {
  return s.impl_->continuation;
}

template <class T>
StagedPath<T>* StepperAccess<T>::staged(const Stepper<T>& s) {
  return s.impl_->core.paths.staged.get();
}

template <class T>
void StepperAccess<T>::accelerations(Stepper<T>& s, const ParticleSet<T>& bodies, double t, T* const out[3],
                                     const StopRequest& stop) {
  s.impl_->accelerations(bodies, t, out, &stop);
}

template <class T>
void StepperAccess<T>::rigid_rates(Stepper<T>& s, const RigidBodySet<T>& bodies, double t, T* const out[13]) {
  s.impl_->rigid_rates(bodies, t, out);
}

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
std::uint64_t Stepper<T>::advance(ParticleSet<T>& io_bodies, T h, std::uint64_t steps, const StopRequest& stop) {
  return impl_->advance(io_bodies, h, steps, stop);
}

template <class T>
AdaptiveStats Stepper<T>::advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances) {
  return impl_->advance_to(io_bodies, t_end, tolerances, {});
}

template <class T>
AdaptiveStats Stepper<T>::advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances,
                                     const StopRequest& stop, const StopRequest& interrupt) {
  return impl_->advance_to(io_bodies, t_end, tolerances, CallStops::of(stop, interrupt));
}

template <class T>
AdaptiveStats Stepper<T>::advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances,
                                     const StopRequest& stop) {
  return impl_->advance_to(io_bodies, t_end, tolerances, CallStops::of(stop, {}));
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
std::uint64_t Stepper<T>::advance(RigidBodySet<T>& io_bodies, T h, std::uint64_t steps, const StopRequest& stop) {
  return impl_->advance(io_bodies, h, steps, stop);
}

template <class T>
AdaptiveStats Stepper<T>::advance_to(RigidBodySet<T>& io_bodies, double t_end, const Tolerances& tolerances) {
  return impl_->advance_to(io_bodies, t_end, tolerances);
}

template <class T>
void Stepper<T>::check_step_size(T h) const {
  const StepperCore<T>& core = impl_->core;
  core.check_step_size(h, core.lowered().particle);
  core.check_step_size(h, core.lowered().rigid);
}

template <class T>
void Stepper<T>::accelerations(const ParticleSet<T>& bodies, double t, T* const out[3]) {
  impl_->accelerations(bodies, t, out);
}

template <class T>
void Stepper<T>::rates(const RigidBodySet<T>& bodies, double t, T* const out[13]) {
  impl_->rigid_rates(bodies, t, out);
}

template <class T>
void Stepper<T>::prepare() {
  impl_->workers.prepare();
}

template <class T>
void Stepper<T>::reserve(std::size_t bodies) {
  AlignedArray<T>::check_count(bodies);  // before padded_count, which would wrap
  if (impl_->core.paths.staged) impl_->core.paths.staged->reserve(padded_count<T>(bodies));
  if (impl_->core.paths.rigid_block) impl_->core.paths.rigid_block->reserve(padded_count<T>(bodies));
  if (impl_->core.paths.block) impl_->core.paths.block->reserve(padded_count<T>(bodies));
  if (impl_->core.paths.implicit) impl_->core.paths.implicit->reserve(padded_count<T>(bodies));
  impl_->fixed.reserve_blocks(padded_count<T>(bodies));
}

template <class T>
std::size_t Stepper<T>::scratch_bytes() const {
  const StepperCore<T>& core = impl_->core;
  const std::size_t staged = core.paths.staged ? core.paths.staged->bytes() : 0;
  const std::size_t probe = core.paths.probe ? core.paths.probe->bytes() : 0;
  const std::size_t rigid = (core.paths.rigid_block ? core.paths.rigid_block->bytes() : 0) +
                            (core.paths.rigid_probe ? core.paths.rigid_probe->bytes() : 0);
  const std::size_t block = (core.paths.block ? core.paths.block->bytes() : 0) +
                            (core.paths.implicit ? core.paths.implicit->bytes() : 0);
  return staged + probe + rigid + block + core.lowered().coupled.springs.bytes() + impl_->fixed.checkpoint_bytes();
}

template <class T>
void Stepper<T>::set_forces(ForceModel<T> forces) {
  impl_->core.use(std::make_shared<const ForceModel<T>>(std::move(forces)));
  impl_->continuation.active = false;
}

template <class T>
void Stepper<T>::set_events(EventOptions<T> events) {
  impl_->fixed.events().set(std::move(events));
}

template <class T>
const std::vector<EventHit<T>>& Stepper<T>::event_hits() const {
  return impl_->fixed.events().hits();
}

template <class T>
bool Stepper<T>::stopped_at_event() const {
  return impl_->fixed.events().stop_time().has_value();
}

template <class T>
const ImplicitStats& Stepper<T>::implicit_stats() const {
  static const ImplicitStats none;
  const auto& implicit = impl_->core.paths.implicit;
  return implicit ? implicit->stats() : none;
}

template <class T>
double Stepper<T>::time() const {
  return impl_->core.clock.time();
}

template <class T>
void Stepper<T>::set_time(double t) {
  if (!std::isfinite(t)) throw Error("time must be finite");
  impl_->core.clock.set(t);
  impl_->continuation.active = false;
}

template <class T>
StepperClock Stepper<T>::clock() const {
  const Clock<T>& c = impl_->core.clock;
  return {c.origin, c.steps, double(c.h), impl_->proposed_step};
}

template <class T>
void Stepper<T>::set_clock(const StepperClock& c) {
  const bool valid = std::isfinite(c.origin) && std::isfinite(c.h) && c.h >= 0 && double(T(c.h)) == c.h &&
                     std::isfinite(c.proposed_step) && c.proposed_step >= 0;
  if (!valid) throw Error("set_clock: the origin, h and proposed step must be finite, h and the proposed step >= 0 "
                          "and h a value of " + std::string(sizeof(T) == 4 ? "float" : "double"));
  impl_->core.clock = Clock<T>{c.origin, c.steps, T(c.h)};
  impl_->proposed_step = c.proposed_step;
  impl_->continuation.active = false;  // it belonged to the old clock
}

template <class T>
const StepperOptions& Stepper<T>::options() const {
  return impl_->core.options;
}

template <class T>
const Method& Stepper<T>::method() const {
  return impl_->core.method;
}
template <class T>
const ForceModel<T>& Stepper<T>::forces() const {
  return impl_->core.forces();
}
template <class T>
Isa Stepper<T>::isa() const {
  return impl_->core.table->isa;
}
template <class T>
bool Stepper<T>::fused() const {
  return impl_->core.paths.fused != nullptr;
}
template <class T>
bool Stepper<T>::fused_rigid() const {
  return impl_->core.paths.rigid != nullptr;
}
template <class T>
unsigned Stepper<T>::threads() const {
  return impl_->workers.jobs().worker_count();
}

template <class T>
unsigned Stepper<T>::chosen_workers() const {
  return impl_->workers.favoured();
}

template <class T>
StiffnessEstimate estimate_stiffness(const ParticleSet<T>& bodies, const ForceModel<T>& forces, double t,
                                     int iterations, StepperOptions options, const StopRequest& stop) {
  // Checked before the stepper is made, as the estimate itself checks it, so that a bad count
  // is the error reported whatever else is wrong.
  if (iterations < 1) throw Error("estimate_stiffness: iterations must be >= 1");
  Stepper<T> stepper(forces, euler, options);
  const auto accelerations = [&](const ParticleSet<T>& set, T* const out[3]) {
    if (stop && stop()) throw Stopped();
    StepperAccess<T>::accelerations(stepper, set, t, out, stop);
  };
  return estimate_stiffness<T>(bodies, accelerations, iterations);
}

template <class T>
StiffnessEstimate estimate_stiffness(const RigidBodySet<T>& bodies, const ForceModel<T>& forces, double t,
                                     int iterations, StepperOptions options, const StopRequest& stop) {
  if (iterations < 1) throw Error("estimate_stiffness: iterations must be >= 1");
  Stepper<T> stepper(forces, euler, options);
  const auto rates = [&](const RigidBodySet<T>& set, T* const out[13]) {
    if (stop && stop()) throw Stopped();
    StepperAccess<T>::rigid_rates(stepper, set, t, out);
  };
  return estimate_stiffness<T>(bodies, rates, iterations);
}

template class Stepper<float>;
template class Stepper<double>;
template StiffnessEstimate estimate_stiffness(const RigidBodySet<float>&, const ForceModel<float>&, double, int,
                                              StepperOptions, const StopRequest&);
template StiffnessEstimate estimate_stiffness(const RigidBodySet<double>&, const ForceModel<double>&, double, int,
                                              StepperOptions, const StopRequest&);
template struct StepperAccess<float>;
template struct StepperAccess<double>;
template StiffnessEstimate estimate_stiffness(const ParticleSet<float>&, const ForceModel<float>&, double, int,
                                              StepperOptions, const StopRequest&);
template StiffnessEstimate estimate_stiffness(const ParticleSet<double>&, const ForceModel<double>&, double, int,
                                              StepperOptions, const StopRequest&);

}  // namespace kinema
