#pragma once
// Scene descriptions: what the JSON files and the C++ builder share.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "kinema/bodies.hpp"
#include "kinema/events.hpp"
#include "kinema/forces.hpp"

namespace kinema {

enum class Precision { single, dual };  // float, double

std::string_view precision_name(Precision p);  // "float" or "double"

// fn.template operator()<float>() or <double>(), as `p` says: the one place a scene's
// precision becomes a type.
template <class Fn>
decltype(auto) with_precision(Precision p, Fn&& fn) {
  if (p == Precision::single) return fn.template operator()<float>();
  return fn.template operator()<double>();
}

// Bodies drawn uniformly from boxes, reproducibly from `seed` on every platform. Rigid
// ones also get a uniformly random orientation and an angular velocity from a box.
// Particles may instead form a Plummer sphere of scale radius `plummer_radius` (positions
// cut at 20 radii), with velocities that put it in equilibrium under the scene's nbody G
// (1 without one), centred at the origin at rest.
struct GenerateSpec {
  std::size_t count = 0;
  std::uint64_t seed = 1;
  Vec3<double> position_min{}, position_max{};
  Vec3<double> velocity_min{}, velocity_max{};
  double mass = 1;
  bool rigid = false;
  Vec3<double> inertia{1, 1, 1};  // principal moments
  Vec3<double> angular_velocity_min{}, angular_velocity_max{};
  double plummer_radius = 0;  // > 0: a Plummer sphere instead of the boxes
};

struct BodySpec {
  Vec3<double> position{};
  Vec3<double> velocity{};
  double mass = 1;
  bool kinematic = false;  // inv_mass 0: forces do not move it
  Vec3<double> force{};    // applied, constant, for the whole run (ParticleSet::apply_force)
  // Per-body parameters, set only where given (see BodyParameters).
  std::optional<double> damping, gravity_factor;
};

// A rigid body resolved to principal axes: `orientation` is that of the principal frame and
// `angular_momentum` is in the world frame, whichever form the scene used.
struct RigidSpec {
  Vec3<double> position{};
  Vec3<double> velocity{};
  Quat<double> orientation{1, 0, 0, 0};
  Vec3<double> angular_momentum{};
  double mass = 1;
  Vec3<double> inertia{1, 1, 1};
  Vec3<double> force{}, torque{};  // applied, constant, for the whole run (world frame)
  std::optional<double> damping, angular_damping, gravity_factor;  // as BodySpec's
  bool kinematic = false;  // moves on at its velocity, does not turn: an anchor for body springs
};

// An event a scene watches (kinema/events.hpp): the built-in kinds, on its particles.
// JSON: {"type": "plane", "normal": [0, 1, 0], "offset": 0, "direction": "down",
// "action": "record"}; {"type": "distance", "point": [..], "radius": r, "direction":
// "inward" | "outward"}; {"type": "speed", "speed": s, "direction": "up" | "down"};
// direction "either" (the default) for any of them, action "record" (default) or "stop".
struct EventSpec {
  std::variant<PlaneEvent, DistanceEvent, SpeedEvent> kind;
  Crossing direction = Crossing::either;
  EventAction action = EventAction::record;
};

struct Scene {
  std::string name = "scene";
  Precision precision = Precision::single;
  std::string method = "rk4";  // or "auto", with a tolerance (see choose_method)
  std::optional<double> tolerance;
  // Error control (methods with an embedded pair): the run then chooses its steps over the
  // duration dt x steps; with one given the other defaults to it.
  std::optional<double> rtol, atol;
  double dt = 0.01;
  std::uint64_t steps = 100;
  std::vector<BodySpec> particles;
  std::vector<RigidSpec> rigid_bodies;
  std::optional<GenerateSpec> generate;
  std::vector<LocalTerm> forces;
  // Coupled terms: N-body gravity, and spring networks in scene order, among the particles
  // or, in a scene of rigid bodies alone, among the rigid bodies' centres. Pair indices
  // count listed particles, then the bodies of network generators in term order, then
  // generated particles (or listed rigid bodies, then generated ones). Body springs join
  // points of rigid bodies, every "body_springs" term's in scene order.
  std::optional<NBody> nbody;
  std::vector<Springs> springs;
  BodySprings body_springs;
  std::vector<EventSpec> events;
  // The particles a spring network generator (chain, grid) added to `particles`, by the
  // generator's JSON path ("forces[0].chain"): errors about them name what the file says.
  struct Generated {
    std::size_t first = 0, count = 0;
    std::string path;
  };
  std::vector<Generated> generated_particles;
};

// Parses a scene; throws kinema::Error naming the JSON path of the first problem,
// e.g. "scene.json: forces[2].k: expected a number >= 0".
Scene parse_scene(std::string_view json_text, std::string_view origin = "scene");
// Files past kMaxSceneBytes are refused: the parsed document takes several times its text,
// and a device such as /dev/zero never ends.
inline constexpr std::size_t kMaxSceneBytes = std::size_t(256) << 20;
Scene load_scene(const std::filesystem::path& path);

// Refuses, before a single body is built, what the scene's text already shows cannot run
// in precision T: a force term out of range or in excess, force parameters or dt (alone or
// times the forces) beyond T, and generated bodies whose mass, inertia or boxes T cannot
// hold or whose state would not fit in this machine's memory. Throws kinema::Error naming
// the JSON path.
template <class T>
void check_scene(const Scene& scene);

// Whether the implicit methods (implicit_euler, ros2) can run the scene: spring networks for
// them to take implicitly, no rigid bodies (listed or generated) and no events.
bool takes_implicit_methods(const Scene& scene);

// Memory this process may use: physical memory, or less under ulimit -v or a cgroup
// (memory.max) limit.
double usable_memory_bytes();

// Bytes of body state (every SoA array, padding aside) the scene's bodies take in T.
template <class T>
double state_bytes(const Scene& scene);

// What one force evaluation of the scene costs, in body-evaluations (about what a body's
// local terms cost): each body, each spring, and under N-body gravity half of every other
// body (its share of the pairs).
double evaluation_cost(const Scene& scene);

// What a run of the scene in T takes at its peak, a bound measured on this tool's own runs:
// its bodies (the state and its copies, the bodies as parsed), its springs (the model's
// copies and the network's layout, in T and in the double of the stiffness estimate), and
// the scratch of coupled scenes (the estimate's vectors, the stages). check_scene refuses a
// scene whose total passes usable_memory_bytes().
struct RunBytes {
  double state = 0, springs = 0, scratch = 0;
  double total() const { return state + springs + scratch; }
};
template <class T>
RunBytes run_bytes(const Scene& scene);

// Listed bodies first, then generated ones (of the matching kind). Generated bodies are
// checked as check_scene does before the first is made.
template <class T>
ParticleSet<T> make_particles(const Scene& scene);
template <class T>
RigidBodySet<T> make_rigid_bodies(const Scene& scene);
template <class T>
ForceModel<T> make_forces(const Scene& scene);
// The scene's events, for Stepper::set_events.
template <class T>
EventOptions<T> make_events(const Scene& scene);

}  // namespace kinema
