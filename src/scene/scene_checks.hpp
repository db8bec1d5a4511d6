#pragma once
// What a scene's text shows cannot run in a precision, refused before any body is built.

#include <cstddef>

#include "kinema/scene.hpp"

namespace kinema {

// Generated bodies whose state would not fit in this machine's memory, or whose mass,
// inertia, boxes or Plummer radius T cannot hold (kinema::Error naming generate.KEY).
template <class T>
void check_generated(const Scene& scene);

// The spring network that made particle i (its JSON path and first body), or null for a
// listed particle.
const Scene::Generated* generator_of(const Scene& scene, std::size_t i);

}  // namespace kinema
