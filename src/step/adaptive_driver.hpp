#pragma once
// The error-controlled driver (Stepper::advance_to): embedded-pair steps on the staged path,
// each accepted or taken back by its error norm, their sizes chosen by a PI controller
// (step_controller.hpp).

#include <cstdint>
#include <optional>

#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "parallel/blocks.hpp"
#include "step/event_watch.hpp"
#include "step/step_controller.hpp"
#include "step/stepper_core.hpp"

namespace kinema {

// What stage 0's accelerations depend on in a set: a CRC-32C of its positions, velocities,
// inverse masses, applied forces and per-body parameters.
template <class T>
std::uint32_t stage_inputs_digest(const ParticleSet<T>& bodies);

// What a call stopped early leaves for the next one to the same end: the size to try, the
// controller's state, and whether stage 0's accelerations are kept in the staged path (with
// the acceleration scale they carry; 0: none).
struct AdaptiveContinuation {
  bool active = false;
  double t_end = 0, rtol = 0, atol = 0, max_step = 0;
  double h = 0;
  StepController::State controller;
  double kept_scale = 0;
  std::size_t bodies = 0;
  // stage_inputs_digest of the set where the call stopped (or that a checkpoint restored with
  // it); none where a record's continuation was restored without its set
  // (CheckpointReader::restore_stepper alone), whose caller restores that set.
  std::optional<std::uint32_t> inputs;

  // Whether a call to `end` with `t` on `set` goes on from here: not after the set was
  // changed in between (its kept accelerations would be another state's).
  template <class T>
  bool continues(double end, const Tolerances& t, const ParticleSet<T>& set) const {
    return active && end == t_end && t.rtol == rtol && t.atol == atol && set.size() == bodies &&
           (!inputs || *inputs == stage_inputs_digest(set));
  }
};

// What ends a call early: `pause` after an accepted step; `interrupt` there too and inside an
// attempt (StepContext::stop: the attempt is taken back). Null: never.
struct CallStops {
  const StopRequest* pause = nullptr;
  const StopRequest* interrupt = nullptr;

  static CallStops of(const StopRequest& pause, const StopRequest& interrupt) {
    return {pause ? &pause : nullptr, interrupt ? &interrupt : nullptr};
  }
  bool after_step() const { return (pause && (*pause)()) || (interrupt && (*interrupt)()); }
};

// The events an adaptive call watches (FixedSteps::watch_adaptive); watch null: none.
template <class T>
struct AdaptiveEvents {
  EventWatch<T>* watch = nullptr;
  EventCall<T> call{};
};

// Steps the bodies from the core's clock to t_end on `workers`, no step longer than
// `max_step`; the last step lands on t_end, unless `stops` say to stop sooner: then
// `continuation` keeps what the next call to t_end goes on from (and a call that continues
// it takes it: Stepper::advance_to has checked that it goes on, or made it inactive). Each
// accepted step is scanned for `events`; a stop event ends the call with
// the set and the clock at it. The request must have passed check_adaptive. Throws
// kinema::Error when the step size underflows.
template <class T>
AdaptiveStats advance_adaptively(StepperCore<T>& core, const Workers& workers, ParticleSet<T>& bodies,
                                 double t_end, const Tolerances& tolerances, double max_step,
                                 AdaptiveContinuation& continuation, const CallStops& stops,
                                 const AdaptiveEvents<T>& events = {});

// Rigid bodies on the rigid path: the same steps, sizes and last step, the error over x, v, q
// and L (RigidBlockPath::attempt); every stage evaluated (no first stage reused), no stop
// requests; `events` as above, on the centres. An initial_step of 0 starts at the estimate
// 0.01 |y| / |f(y)| over the 13 components, as the particles' over their 6.
template <class T>
AdaptiveStats advance_adaptively(StepperCore<T>& core, const Workers& workers, RigidBodySet<T>& bodies,
                                 double t_end, const Tolerances& tolerances, const AdaptiveEvents<T>& events = {});

}  // namespace kinema
