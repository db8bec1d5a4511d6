#pragma once
// Accuracy: reference solutions, error measures, and the cheapest method for a tolerance.
//
// Errors are measured at the end of a run, in phase space: the largest over bodies of
// |x - x_ref| + |v - v_ref| (scene units, seconds as the time unit) plus, for rigid
// bodies, the orientation error in radians. Velocities count because positions alone
// hide first-order errors (semi-implicit Euler's positions are second order).

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "kinema/adaptive.hpp"
#include "kinema/methods.hpp"
#include "kinema/scene.hpp"

namespace kinema {

// Final positions and velocities (particles, then rigid bodies) and rigid orientations.
struct BodyStates {
  std::vector<Vec3<double>> positions, velocities;
  std::vector<Quat<double>> orientations;
};

// The scene with its bodies made explicit (generated ones listed) and at most `max_bodies`
// of each kind kept, picked evenly. Local forces act body by body, so a sample of bodies
// measures the error of the whole scene.
Scene sample_bodies(const Scene& scene, std::size_t max_bodies);

// Runs `steps` steps of duration / steps with `method` on one thread, in the scene's precision.
// The analyses here poll `stop` between calls of a few milliseconds of stepping (and between
// force evaluations of a stiffness estimate); once it returns true they throw kinema::Stopped.
BodyStates simulate(const Scene& scene, const Method& method, std::uint64_t steps, double duration,
                    const StopRequest& stop = {});

// An error-controlled run (rtol = atol = tolerance, steps at most max_step) of a method
// with an embedded pair over the duration: the final states and the force evaluations.
struct AdaptiveRun {
  BodyStates states;
  std::uint64_t evaluations = 0;
};
AdaptiveRun simulate_adaptive(const Scene& scene, const Method& method, double tolerance, double duration,
                              double max_step = std::numeric_limits<double>::infinity(),
                              const StopRequest& stop = {});

// max over bodies of |x - x_ref| + |v - v_ref| (+ the rotation angle between q and q_ref);
// infinity where a value is not finite. kinema::Error when the two hold different numbers
// of bodies.
double state_error(const BodyStates& states, const BodyStates& reference);

// Closed-form final states when the scene has them: every body under one central
// attractor on an elliptic orbit (Kepler's equation), or under any mix of gravity, linear
// drag and one spring (a damped oscillator). nullopt otherwise; kinema::Error for a duration
// that is not finite or is negative (reference_states too).
std::optional<BodyStates> analytic_states(const Scene& scene, double duration);

struct Reference {
  BodyStates states;
  double error = 0;   // estimated error of the reference itself (0 when analytic)
  bool analytic = false;
  std::uint64_t steps = 0;  // of the numerical reference
};

// The analytic solution, else rk4 in double with `steps` steps, its own error estimated
// from a run at half as many steps (Richardson: difference / 15).
Reference reference_states(const Scene& scene, double duration, std::uint64_t steps, const StopRequest& stop = {});

struct MethodChoice {
  const Method* method = nullptr;
  std::uint64_t steps = 0;  // dt = duration / steps exactly (fixed steps)
  double dt = 0;
  // Set when error-controlled steps of an embedded pair are the cheapest: rtol = atol =
  // this over the duration; steps and dt then describe nothing.
  std::optional<double> step_tolerance;
  Precision precision = Precision::dual;  // the scene's, or float where its round-off allows
  double evaluations = 0;                 // force evaluations the choice costs
  double estimated_error = 0;
  std::string reason;       // one line: what each candidate would cost
  // Every method that can reach the tolerance, with the step count the pilots estimate and
  // what it costs in force evaluations (an implicit method's solves: each iteration as one).
  struct Candidate {
    const Method* method;
    std::uint64_t steps;
    double evaluations;
  };
  std::vector<Candidate> candidates;
};

// The named method and step count with the fewest force evaluations whose estimated error
// over the scene's duration (dt x steps) stays under `tolerance`. On a particle scene with
// springs (and no events) the implicit methods are tried too, each iteration of their
// solves counted as a force evaluation, their step bounded by their explicit part's on the
// scene without its springs. Each method's error comes
// from pilot runs on a sample of bodies at N, 2N and 4N steps (Richardson, with the observed
// order), and the choice is checked again at its own step count. No step past a method's
// largest stable step on the scene (from a stiffness estimate at its start) is proposed, and
// a method with none is not tried. The embedded pairs are also tried with error-controlled
// steps (rtol = atol from the tolerance down by tens, each run's error measured against one
// a hundred times tighter). A double scene is run in float when float's round-off, measured
// by the chosen configuration in both precisions, stays ten times under the tolerance: float
// steps cost half (`float_allowed` false: the scene's precision, as a caller that named it
// asks). Throws kinema::Error when the tolerance is not positive or cannot be reached.
MethodChoice choose_method(const Scene& scene, double tolerance, const StopRequest& stop = {},
                           bool float_allowed = true);

}  // namespace kinema
