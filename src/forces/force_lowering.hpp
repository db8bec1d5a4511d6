#pragma once
// The force model lowered to the kernels' parameters: every local term summed by kind and
// converted to the stepper's precision, once per stepper.

#include <span>

#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"

namespace kinema {

template <class T>
struct LoweredForces {
  kernels::LocalForces<T> particle;       // what a particle feels (point forces push rigid bodies only)
  kernels::LocalForces<T> rigid;          // what a rigid body's centre feels
  kernels::RotationalForces<T> rotation;  // torques on rigid bodies
  CoupledForces<T> coupled;               // forces between particles
};

// Throws kinema::Error when a parameter, or a sum of them, overflows T.
template <class T>
LoweredForces<T> lower_forces(std::span<const LocalTerm> terms);

// Throws kinema::Error when `scale` (sigma h for Runge-Kutta kernels, see
// kernels::acceleration_scale) times a local parameter or N-body's G overflows T; `h` only
// names the step.
template <class T>
void check_scaled_forces(const kernels::LocalForces<T>& forces, const CoupledForces<T>& coupled, T scale, T h);
// The same for a set's own parameters: the largest gravity factor times gravity, the largest
// damping rates, times the step.
template <class T>
void check_scaled_parameters(const BodyParameters<T>& own, const kernels::LocalForces<T>& forces, T scale, T h);

}  // namespace kinema
