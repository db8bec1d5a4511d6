#pragma once
// A rigid body's world angular momentum from its angular velocity, for scenes that give the
// latter (listed bodies and generated ones).

#include "kinema/bodies.hpp"

namespace kinema {

// L = R diag(I) R^T omega, all in double.
inline Vec3<double> momentum_from_velocity(const Quat<double>& q, const Vec3<double>& inertia,
                                           const Vec3<double>& omega) {
  Vec3<double> body = rotate({q[0], -q[1], -q[2], -q[3]}, omega);
  for (int d = 0; d < 3; ++d) body[d] *= inertia[d];
  return rotate(q, body);
}

}  // namespace kinema
