#pragma once
// Random bodies for a scene's "generate": uniform boxes of particles or rigid bodies, and
// Plummer spheres. Only exactly rounded operations on a 64-bit Mersenne Twister's bits: the
// same bodies on every platform for a seed.

#include <functional>
#include <random>

#include "kinema/bodies.hpp"
#include "kinema/scene.hpp"

namespace kinema {

// Uniform in [lo, hi] from the top 53 bits of a 64-bit Mersenne Twister: the same numbers
// on every platform (std::uniform_real_distribution is implementation-defined).
inline double uniform(std::mt19937_64& rng, double lo, double hi) {
  const double u = double(rng() >> 11) * 0x1.0p-53;
  return lo + (hi - lo) * u;
}

// L = R diag(I) R^T omega, all in double.
inline Vec3<double> momentum_from_velocity(const Quat<double>& q, const Vec3<double>& inertia,
                                    const Vec3<double>& omega) {
  Vec3<double> body = rotate({q[0], -q[1], -q[2], -q[3]}, omega);
  for (int d = 0; d < 3; ++d) body[d] *= inertia[d];
  return rotate(q, body);
}

// The scene's generated particles (box or Plummer sphere), added to `set`.
template <class T>
void add_generated_particles(const Scene& scene, ParticleSet<T>& set);
// Calls add(spec) for each of the scene's generated rigid bodies, in order.
void for_each_generated_rigid_body(const GenerateSpec& generate, const std::function<void(const RigidSpec&)>& add);

}  // namespace kinema
