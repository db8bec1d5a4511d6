#pragma once
// Error control: what Stepper::advance_to is asked to meet, and what it reports.

#include <cstdint>
#include <limits>

#include "kinema/error.hpp"  // StopRequest

namespace kinema {

// Error control for Stepper::advance_to. A step is accepted when the weighted RMS norm of
// its error estimate is at most 1: the mean over every body's position and velocity
// components of (e / (atol + rtol max(|y_old|, |y_new|)))^2, square-rooted, as SUNDIALS
// defines it (e the difference of the pair's two solutions).
struct Tolerances {
  double rtol = 1e-6;          // finite, >= 0
  double atol = 1e-6;          // finite, >= 0 (length and velocity units); not both 0
  double initial_step = 0;     // 0: 0.01 |y| / |f(y)| in the same norm, at most t_end - t
  double max_step = std::numeric_limits<double>::infinity();
  // Also cap the steps at the method's largest stable step for the bodies at the call's start
  // (estimate_stiffness, kinema/stability.hpp, in T: about 60 force evaluations, so once per
  // run rather than once per frame).
  bool limit_to_stable_step = false;
};

struct AdaptiveStats {
  std::uint64_t accepted = 0, rejected = 0;
  std::uint64_t evaluations = 0;  // force evaluations (stages; a reused one is not counted)
  double smallest_step = 0, largest_step = 0;  // of the accepted steps
  double next_step = 0;  // the controller's proposal: a good initial_step for a next call
  // The call returned before t_end because its stop request said so. The next advance_to call
  // with the same t_end and tolerances goes on exactly where it stopped (the controller's state
  // and the first-same-as-last stage are kept, in the stepper and in a checkpoint of it): the
  // bits are those of one call that never stopped. Any other call drops what was kept, and so
  // does a set changed in between (positions, velocities, masses, applied forces, per-body
  // parameters: the kept stage would be another state's); what callbacks read is the caller's
  // to keep as it was.
  bool stopped = false;
};


}  // namespace kinema
