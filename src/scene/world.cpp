#include "kinema/world.hpp"

#include <algorithm>

#include "kinema/diagnostics.hpp"
#include "kinema/error.hpp"
#include "step/adaptive_driver.hpp"
#include "step/stepper_access.hpp"

namespace kinema {

template <class T>
World<T>::World(const Scene& scene, const Method& method, StepperOptions options)
    : forces_(std::make_shared<const ForceModel<T>>(make_forces<T>(scene))),
      particles(make_particles<T>(scene)),
      rigid(make_rigid_bodies<T>(scene)),
      particle_stepper_(forces_, method, options),
      rigid_stepper_(forces_, method, options),
      scene_events_(scene.events) {}

template <class T>
void World<T>::watch_events() {
  // One stepper watches: the other set's crossings would go unseen, and a stop would end one
  // set's call and not the other's.
  if (particles.size() > 0 && rigid.size() > 0 && !scene_events_.empty()) {
    throw Error("World::watch_events: events watch bodies of one kind; this world has particles and rigid bodies");
  }
  Scene events;
  events.events = scene_events_;
  (rigid_only() ? rigid_stepper_ : particle_stepper_).set_events(make_events<T>(events));
}

// Makes the idle kind's clock the main one's as a call leaves, by a throw too (the steps
// completed before it stand). A clock copied from a stepper is valid: set_clock cannot throw.
template <class T>
struct World<T>::ClockFollower {
  World& world;
  ~ClockFollower() { world.follow_main_clock(); }
};

template <class T>
void World<T>::advance(T h, std::uint64_t steps) {
  const ClockFollower follow{*this};
  // An empty world's clock goes on too (as under advance_to): on its main stepper, the particles'.
  if (particles.size() > 0 || rigid.size() == 0) particle_stepper_.advance(particles, h, steps);
  if (rigid.size() > 0) rigid_stepper_.advance(rigid, h, steps);
  event_hits_ = main_stepper().event_hits();
}

// A kind with no bodies takes no steps: its stepper's clock is the main one's, so that bodies
// added to it later start at the world's time, not where it was last stepped.
template <class T>
void World<T>::follow_main_clock() {
  if (particles.size() > 0 && rigid.size() > 0) return;  // both stepped
  Stepper<T>& idle = rigid_only() ? particle_stepper_ : rigid_stepper_;
  idle.set_clock(main_stepper().clock());
}

template <class T>
std::uint64_t World<T>::advance(T h, std::uint64_t steps, const StopRequest& stop) {
  const ClockFollower follow{*this};
  const std::uint64_t chunk = steps_per_call();
  std::uint64_t done = 0;
  event_hits_.clear();
  while (done < steps && !(stop && stop())) {
    const std::uint64_t n = std::min(chunk, steps - done);
    if (rigid_only()) {  // its events, its stop
      const std::uint64_t taken = rigid_stepper_.advance(rigid, h, n, stop);
      event_hits_.insert(event_hits_.end(), rigid_stepper_.event_hits().begin(), rigid_stepper_.event_hits().end());
      done += taken;
      if (taken < n || rigid_stepper_.stopped_at_event()) break;
      continue;
    }
    // A coupled step can outlast a call's budget: the particles poll inside it too.
    const bool own_clock = particles.size() > 0 || rigid.size() == 0;  // an empty world's too
    const std::uint64_t taken = own_clock ? particle_stepper_.advance(particles, h, n, stop) : n;
    const auto& hits = particle_stepper_.event_hits();
    event_hits_.insert(event_hits_.end(), hits.begin(), hits.end());
    if (rigid.size() > 0) advance_rigid(h, taken, taken < n);
    done += taken;
    if (taken < n || particle_stepper_.stopped_at_event()) break;
  }
  return done;
}

template <class T>
std::uint64_t World<T>::steps_per_call() const {
  constexpr double kWorkPerCall = double(1 << 22);
  const double n = double(particles.size() + rigid.size());
  const double body = 1 + double(forces_->springs().size()) / std::max(n, 1.0) + (forces_->nbody() ? n / 2 : 0);
  const double evaluations = main_stepper().method().evaluations();
  return std::uint64_t(std::max(1.0, kWorkPerCall / (std::max(n, 64.0) * body * evaluations)));
}

template <class T>
double World<T>::time() const {
  return main_stepper().time();
}

template <class T>
double World<T>::total_energy(const StopRequest& stop) const {
  return (particles.size() > 0 ? energy(particles, *forces_, stop).total() : 0) +
         (rigid.size() > 0 ? energy(rigid, *forces_).total() : 0);
}

// A call cut short keeps the rigid bodies' applied forces for its rest, as the particles'.
template <class T>
void World<T>::advance_rigid(T h, std::uint64_t steps, bool cut_short) {
  const bool keeps = rigid.keeps_forces();
  rigid.keep_forces(keeps || cut_short);
  try {
    rigid_stepper_.advance(rigid, h, steps);
  } catch (...) {
    rigid.keep_forces(keeps);
    throw;
  }
  rigid.keep_forces(keeps);
}

template <class T>
AdaptiveStats World<T>::advance_to(double t_end, const Tolerances& tolerances, const StopRequest& stop,
                                   const StopRequest& interrupt) {
  const ClockFollower follow{*this};
  if (rigid.size() == 0) {
    const AdaptiveStats stats = particle_stepper_.advance_to(particles, t_end, tolerances, stop, interrupt);
    event_hits_ = particle_stepper_.event_hits();
    return stats;
  }
  if (particles.size() > 0) {
    throw Error("error-controlled steps take one kind of body; the scene has particles and rigid bodies");
  }
  const AdaptiveStats stats = rigid_stepper_.advance_to(rigid, t_end, tolerances);
  event_hits_ = rigid_stepper_.event_hits();
  return stats;
}

template <class T>
bool World<T>::finite() const {
  return all_finite(particles) && all_finite(rigid);
}

template <class T>
void World<T>::save(CheckpointWriter& out) const {
  out.add(particles, particle_stepper_);
  out.add(rigid, rigid_stepper_);
}

template <class T>
void World<T>::restore(const CheckpointReader& in) {
  if (in.records() != 2) {
    throw Error("checkpoint: " + std::to_string(in.records()) + " records where a world has 2 (particles, rigid bodies)");
  }
  ParticleSet<T> p = in.particles(0, particle_stepper_);
  RigidBodySet<T> r = in.rigid_bodies(1, rigid_stepper_);
  if (p.size() != particles.size() || r.size() != rigid.size()) {
    throw Error("checkpoint: " + std::to_string(p.size()) + " particles and " + std::to_string(r.size()) +
                " rigid bodies where this world has " + std::to_string(particles.size()) + " and " +
                std::to_string(rigid.size()));
  }
  // Each checks before it changes anything; a rigid stepper has no error control to go on
  // from, so its clock is all there is to put back.
  const StepperClock before = rigid_stepper_.clock();
  in.restore_stepper(1, rigid_stepper_);
  try {
    in.restore_stepper(0, particle_stepper_);
  } catch (...) {
    rigid_stepper_.set_clock(before);
    throw;
  }
  particles = std::move(p);
  rigid = std::move(r);
  // The particles' continuation goes on with the set the record holds: an edit after this is
  // seen as a change (Stepper::advance_to starts afresh).
  AdaptiveContinuation& cont = StepperAccess<T>::continuation(particle_stepper_);
  if (cont.active) cont.inputs = stage_inputs_digest(particles);
}

template class World<float>;
template class World<double>;

}  // namespace kinema
