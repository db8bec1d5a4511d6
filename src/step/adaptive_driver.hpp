#pragma once
// The error-controlled driver (Stepper::advance_to): embedded-pair steps on the staged path,
// each accepted or taken back by its error norm, their sizes chosen by a PI controller
// (step_controller.hpp).

#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "parallel/blocks.hpp"
#include "step/stepper_core.hpp"

namespace kinema {

// Steps the bodies from the core's clock to t_end on `workers`, no step longer than
// `max_step`; the last step lands on t_end. The request must have passed check_adaptive.
// Throws kinema::Error when the step size underflows.
template <class T>
AdaptiveStats advance_adaptively(StepperCore<T>& core, const Workers& workers, ParticleSet<T>& bodies,
                                 double t_end, const Tolerances& tolerances, double max_step);

}  // namespace kinema
