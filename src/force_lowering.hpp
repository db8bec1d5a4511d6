#pragma once
// The force model lowered to the kernels' parameters: every local term summed by kind and
// converted to the stepper's precision, once per stepper.

#include <span>
#include <string>

#include "coupled_forces.hpp"
#include "kernels/kernels.hpp"
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
// kernels::acceleration_scale) times a parameter overflows T; `h` only names the step.
template <class T>
void check_scaled_forces(const kernels::LocalForces<T>& forces, T scale, T h);

// "float" or "double".
template <class T>
std::string type_name() {
  return sizeof(T) == 4 ? "float" : "double";
}

// The shortest text, of at most `digits` significant digits, that reads back as the same
// value (as a float when `as_float`): "1e+39", not "9.9999999999999994e+38" nor "0.000000".
std::string shortest_text(double x, int digits = 17, bool as_float = false);
template <class T>
std::string shortest_text(T x) {
  return sizeof(T) == 4 ? shortest_text(double(x), 9, true) : shortest_text(double(x), 17);
}

}  // namespace kinema
