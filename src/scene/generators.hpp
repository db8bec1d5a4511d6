#pragma once
// Random bodies for a scene's "generate": uniform boxes of particles or rigid bodies, and
// Plummer spheres, from a 64-bit Mersenne Twister seeded by the scene.

#include <functional>

#include "kinema/bodies.hpp"
#include "kinema/scene.hpp"

namespace kinema {

// The scene's generated particles (box or Plummer sphere), added to `set`.
template <class T>
void add_generated_particles(const Scene& scene, ParticleSet<T>& set);
// Calls add(spec) for each of the scene's generated rigid bodies, in order.
void for_each_generated_rigid_body(const Scene& scene, const std::function<void(const RigidSpec&)>& add);

}  // namespace kinema
