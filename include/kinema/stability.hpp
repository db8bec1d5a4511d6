#pragma once
// Where explicit methods stay stable, and how stiff a scene is: the largest step a method
// can take on a scene, known before a single step.
//
// A method is judged on one linear mode, x' = v, v' = a x + b v, whose eigenvalues are the
// pair lambda, conj(lambda): a step of size h is stable when the spectral radius of the
// step's 2 x 2 matrix is at most 1 (to rounding). For a Runge-Kutta method that is
// |R(h lambda)| <= 1; kick-drift methods are judged on the same mode. A real dominant
// eigenvalue -r is taken as damping (a = 0, b = -r: eigenvalues 0 and -r), any other as a
// damped oscillation (a = -|lambda|^2, b = 2 Re lambda).

#include <functional>
#include <type_traits>

#include "kinema/bodies.hpp"
#include "kinema/methods.hpp"

namespace kinema {

// The dominant eigenvalue (pair) of the force model's Jacobian d(v, a)/d(x, v) at a state.
struct StiffnessEstimate {
  double magnitude = 0;  // |lambda| (1/s); 0 when the forces do not depend on the state
  double angle = 0;      // from the negative real axis, 0 (decay) to pi/2 (undamped oscillation);
                         // a growing mode is taken as its decaying mirror
  int evaluations = 0;   // force evaluations it took
};

// Writes the accelerations (force / mass; 0 for bodies with inv_mass 0) the forces give
// `bodies` into out[0..2], padded_size() each: Stepper::accelerations at a fixed time.
template <class T>
using AccelerationFn = std::function<void(const ParticleSet<T>& bodies, T* const out[3])>;

// Restarted Arnoldi with Jacobian-vector products by finite differences of the accelerations:
// no matrix is formed. Cycles of up to 20 products build a Krylov basis and J's projection on
// it; the projection's dominant eigenvalue or pair (real or complex: an oscillation's
// +-i omega) comes from fitting H^2 u = p H u + q u, the roots of x^2 - p x - q. Positions are
// first scaled by a rough |lambda| from 8 power steps, so that J is close to normal. Costs
// `iterations` + 17 calls of `accelerations`, in T, and up to 21 vectors of 6 doubles per body
// (fewer past 512 MiB). For a force model, estimate_stiffness(bodies, forces, ...) in
// kinema/stepper.hpp does this with a stepper's accelerations. Where the rates about the
// state are not finite (a force that overflows, a state of inf or NaN) the magnitude is inf
// or NaN, which the functions below refuse or answer for, never as a state without modes.
template <class T>
StiffnessEstimate estimate_stiffness(const ParticleSet<T>& bodies,
                                     const std::type_identity_t<AccelerationFn<T>>& accelerations,
                                     int iterations = 120);

// Rigid bodies: writes the rates of the 13 state components of every body (padded_size()
// each) into out: the velocity, acceleration, dq/dt and torque (dL/dt).
template <class T>
using RigidRatesFn = std::function<void(const RigidBodySet<T>& bodies, T* const out[13])>;

// The same for rigid bodies, over the state (x, v, q, L): the Jacobian has the rotational
// degrees of freedom too, so a stiff spring at a body point (a fast rotational mode) shows.
// Positions and orientations are balanced against velocities and angular momenta alike. Up to
// 21 vectors of 13 doubles per body. For a force model, estimate_stiffness(bodies, forces,
// ...) in kinema/stepper.hpp.
template <class T>
StiffnessEstimate estimate_stiffness(const RigidBodySet<T>& bodies,
                                     const std::type_identity_t<RigidRatesFn<T>>& rates, int iterations = 120);

// Where a linearly implicit method (implicit_euler, ros2) meets the estimate's mode: in its
// Jacobian J (the springs' mode: no step bounds it), or in the forces it steps explicitly
// (every force but the springs), whose mode J leaves out. J still holds the positions'
// dependence on the velocities (x' = v), so to those forces implicit_euler is symplectic
// Euler: stable on an undamped oscillation up to h |lambda| = 2, where Euler never is.
// Other methods ignore it.
enum class ImplicitMode { in_jacobian, explicit_forces };

// The largest h > 0 up to which every step is stable for the estimate's mode (0: none, as
// for Euler on an undamped oscillation; infinity when the estimate's magnitude is 0, or for
// an implicit method's in_jacobian mode). kinema::Error for a magnitude that is NaN.
double largest_stable_step(const Method& method, const StiffnessEstimate& estimate,
                           ImplicitMode mode = ImplicitMode::in_jacobian);

// How much the estimate's mode grows (or shrinks) per step of size h under the method: the
// spectral radius of the step's 2 x 2 matrix (see above); infinity where the step's entries
// overflow double (h far past the stable step).
double growth_per_step(const Method& method, const StiffnessEstimate& estimate, double h,
                       ImplicitMode mode = ImplicitMode::in_jacobian);

// h |lambda| at the edge of the stability region on the negative real axis (damping at the
// rate |lambda|) and on the imaginary axis (an undamped oscillation at |lambda|): 2 and 0
// for euler, about 2.785 and 2.828 for rk4, 2 on the imaginary axis for the symplectic
// methods. Methods unstable on the imaginary axis near 0 report 0 there, or the tiny
// interval where their growth stays within rounding.
struct StabilityLimits {
  double real_axis = 0, imaginary_axis = 0;
};
StabilityLimits stability_limits(const Method& method);

extern template StiffnessEstimate estimate_stiffness(const ParticleSet<float>&, const AccelerationFn<float>&, int);
extern template StiffnessEstimate estimate_stiffness(const ParticleSet<double>&, const AccelerationFn<double>&, int);
extern template StiffnessEstimate estimate_stiffness(const RigidBodySet<float>&, const RigidRatesFn<float>&, int);
extern template StiffnessEstimate estimate_stiffness(const RigidBodySet<double>&, const RigidRatesFn<double>&, int);

}  // namespace kinema
