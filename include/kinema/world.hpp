#pragma once
// World: what a scene builds, in one precision, ready to step. Its particles and rigid
// bodies (each set with its own stepper and clock), its forces, one job system.

#include <cstdint>
#include <memory>
#include <vector>

#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "kinema/checkpoint.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "kinema/scene.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

template <class T>
class World {
 public:
  // Builds the forces, then the bodies, then one stepper per kind of body (particles,
  // rigid bodies), sharing the one force model; each kind has its own clock. With
  // options.jobs null they use the process-wide default_job_system(options.threads).
  // Throws kinema::Error as the scene builders and Stepper do.
  World(const Scene& scene, const Method& method, StepperOptions options = {});
  World(World&&) noexcept = default;

  void advance(T h, std::uint64_t steps);
  // The same steps, in calls of about a few milliseconds each (steps_per_call), polling
  // `stop` between them, and inside a step of coupled terms as Stepper::advance with a stop
  // does (a step abandoned is not taken); returns the steps taken, fewer than asked once
  // `stop` returned true. The bits are those of one call.
  std::uint64_t advance(T h, std::uint64_t steps, const StopRequest& stop);
  // Watches the scene's events (Scene::events) from the next advance on, on the main
  // stepper's bodies (a scene with events has one kind: kinema::Error for a world of both);
  // a world watches none until asked (the analyses that build worlds from a scene step it to
  // fixed times).
  void watch_events();
  // The events found by the last advance call, in order, and whether
  // one of them stopped it (the world then at its time; the steps returned count the cut one).
  const std::vector<EventHit<T>>& event_hits() const { return event_hits_; }
  bool stopped_at_event() const { return main_stepper().stopped_at_event(); }
  // Steps of about the same work: 2^22 body-evaluations, where a body costs its springs too
  // and, under N-body gravity, half of every body again (its share of the pairs).
  std::uint64_t steps_per_call() const;
  // Error-controlled steps to t_end (Stepper::advance_to), for a world of one kind of body
  // (kinema::Error when it has both). With `stop` and `interrupt`, as Stepper::advance_to
  // with them for particles; rigid bodies run to t_end without polling them.
  AdaptiveStats advance_to(double t_end, const Tolerances& tolerances, const StopRequest& stop = {},
                           const StopRequest& interrupt = {});
  double time() const;
  // Kinetic (with rotation) + potential, both sets; `stop` as in energy (kinema/diagnostics.hpp).
  double total_energy(const StopRequest& stop = {}) const;
  bool finite() const;
  // Checkpoints (kinema/checkpoint.hpp): save adds two records, the particles and the rigid
  // bodies with their steppers; restore takes both back, all or nothing (kinema::Error, the
  // world as it was, for a checkpoint of another scene, model, method or precision).
  void save(CheckpointWriter& out) const;
  void restore(const CheckpointReader& in);

  const ForceModel<T>& forces() const { return *forces_; }
  const Stepper<T>& particle_stepper() const { return particle_stepper_; }
  const Stepper<T>& rigid_stepper() const { return rigid_stepper_; }
  // The stepper that moves the world's bodies: the particles', or the rigid bodies' when
  // the world has no particles.
  const Stepper<T>& main_stepper() const { return rigid_only() ? rigid_stepper_ : particle_stepper_; }

 private:
  std::shared_ptr<const ForceModel<T>> forces_;  // declared first: built before the bodies

 public:
  ParticleSet<T> particles;
  RigidBodySet<T> rigid;

 private:
  void advance_rigid(T h, std::uint64_t steps, bool cut_short);
  void follow_main_clock();
  struct ClockFollower;
  bool rigid_only() const { return particles.size() == 0 && rigid.size() > 0; }

  Stepper<T> particle_stepper_, rigid_stepper_;
  std::vector<EventHit<T>> event_hits_;
  std::vector<EventSpec> scene_events_;
};

extern template class World<float>;
extern template class World<double>;

}  // namespace kinema
