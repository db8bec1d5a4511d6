#pragma once
// What a stepper refuses before any body moves: each check throws kinema::Error naming the
// value and the limit it breaks.

#include <string>

#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"
#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "kinema/methods.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

// A step size positive and finite in T (what it does to the forces: check_scaled_forces).
template <class T>
void check_step_positive(T h);

// Springs must not reach past the set.
template <class T>
void check_reach(const CoupledForces<T>& coupled, const ParticleSet<T>& bodies);

// An enumeration given a value none of its names has (a cast, a corrupt host setting):
// kinema::Error "<field> has no value N". `last`: its last name.
template <class E>
void check_named(const std::string& field, E value, E last) {
  if (static_cast<int>(value) < 0 || static_cast<int>(value) > static_cast<int>(last)) {
    throw Error(field + " has no value " + std::to_string(static_cast<int>(value)));
  }
}

// The options' enumerations named values; the implicit solves' tolerance and iteration cap;
// the clamp's speed limits, and their squares, finite and > 0 in T.
template <class T>
void check_stepper_options(const StepperOptions& options);

// advance_to's request: a method with a pair, sane tolerances, t_end not before `now`.
void check_adaptive(const Method& method, double t_end, const Tolerances& tolerances, double now);

// Throws kinema::Error when no step could meet the tolerances in T: atol + rtol Y under a
// sixteenth of an ulp of Y, the bodies' largest |position| + |velocity| component.
template <class T>
void check_tolerance_floor(const ParticleSet<T>& bodies, const Tolerances& tolerances);
// The same on the centres, then on the orientations and angular momenta.
template <class T>
void check_tolerance_floor(const RigidBodySet<T>& bodies, const Tolerances& tolerances);

}  // namespace kinema
