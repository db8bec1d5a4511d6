#pragma once
// Scene descriptions: what the JSON files and the C++ builder share.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"

namespace kinema {

enum class Precision { single, dual };  // float, double

std::string_view precision_name(Precision p);  // "float" or "double"

// Bodies drawn uniformly from boxes, reproducibly from `seed` on every platform.
struct GenerateSpec {
  std::size_t count = 0;
  std::uint64_t seed = 1;
  Vec3<double> position_min{}, position_max{};
  Vec3<double> velocity_min{}, velocity_max{};
  double mass = 1;
};

struct BodySpec {
  Vec3<double> position{};
  Vec3<double> velocity{};
  double mass = 1;
  bool kinematic = false;  // inv_mass 0: forces do not move it
};

struct Scene {
  std::string name = "scene";
  Precision precision = Precision::single;
  std::string method = "rk4";
  double dt = 0.01;
  std::uint64_t steps = 100;
  std::vector<BodySpec> particles;
  std::optional<GenerateSpec> generate;
  std::vector<LocalTerm> forces;
};

// Parses a scene; throws kinema::Error naming the JSON path of the first problem,
// e.g. "scene.json: forces[2].k: expected a number >= 0".
Scene parse_scene(std::string_view json_text, std::string_view origin = "scene");
Scene load_scene(const std::filesystem::path& path);

// Listed bodies first, then generated ones.
template <class T>
ParticleSet<T> make_particles(const Scene& scene);
template <class T>
ForceModel<T> make_forces(const Scene& scene);

}  // namespace kinema
