#pragma once
// The coupled terms of a scene: "nbody", "springs" given as pairs or made by a chain or grid
// generator (which also makes the bodies it joins), and "body_springs" between rigid bodies.

#include <cstddef>
#include <span>
#include <string>
#include <string_view>

#include "kinema/scene.hpp"
#include "scene/json_node.hpp"

namespace kinema {

// A generator makes at most this many bodies (a 1024 x 1024 cloth): the scene text is
// short, what it asks for is not (a body and four springs take about 200 bytes here).
inline constexpr std::size_t kMaxNetworkBodies = std::size_t(1) << 20;
// Listed particles and the bodies of every generator together, at most.
inline constexpr std::size_t kMaxNetworkScene = std::size_t(1) << 22;

bool is_coupled_force(std::string_view type);
// Adds the term `n` to the scene: its NBody, or a network (a generator's bodies go to the
// end of scene.particles, so they follow the listed particles and earlier generators).
void parse_coupled_force(const scene_json::Node& n, const std::string& type, Scene& scene);
// Once every term is read: spring pairs join the bodies of a scene of one kind (particles,
// or rigid bodies' centres), body springs rigid bodies, and each spring's bodies must exist.
// `terms[k]` is the node of scene.springs[k]; `body_terms` the "body_springs" terms in order.
void check_coupled(const Scene& scene, std::span<const scene_json::Node> terms,
                   std::span<const scene_json::Node> body_terms);
// The scene's particles and rigid bodies, listed and generated; whether it has both.
std::size_t particle_count(const Scene& scene);
std::size_t rigid_count(const Scene& scene);
bool mixed_bodies(const Scene& scene);

}  // namespace kinema
