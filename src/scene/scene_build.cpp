// Bodies and forces from a parsed scene: listed bodies first, then generated ones.
#include "kinema/scene.hpp"

#include <string>

#include "kinema/error.hpp"
#include "scene/generators.hpp"
#include "scene/scene_checks.hpp"

namespace kinema {
namespace {

template <class T>
Vec3<T> converted(const Vec3<double>& v) {
  return {T(v[0]), T(v[1]), T(v[2])};
}

bool nonzero(const Vec3<double>& v) {
  return v[0] != 0 || v[1] != 0 || v[2] != 0;
}

// The applied forces a scene gives its bodies act for the whole run: the set keeps them.
// `apply` may throw kinema::Error (a value too large for T): it names the body's list entry.
template <class Apply>
void apply_scene_load(const char* list, std::size_t i, Apply&& apply) {
  try {
    apply();
  } catch (const Error& e) {
    throw Error(std::string(list) + "[" + std::to_string(i) + "]: " + e.what() + " in this precision");
  }
}

}  // namespace

template <class T>
RigidBodySet<T> make_rigid_bodies(const Scene& scene) {
  check_generated<T>(scene);
  RigidBodySet<T> set;
  const bool generated = scene.generate && scene.generate->rigid;
  set.reserve(scene.rigid_bodies.size() + (generated ? scene.generate->count : 0));
  auto add = [&](const RigidSpec& b) {
    set.add({converted<T>(b.position), converted<T>(b.velocity),
             {T(b.orientation[0]), T(b.orientation[1]), T(b.orientation[2]), T(b.orientation[3])},
             converted<T>(b.angular_momentum), T(b.mass), converted<T>(b.inertia)});
  };
  for (const RigidSpec& b : scene.rigid_bodies) add(b);
  for (std::size_t i = 0; i < scene.rigid_bodies.size(); ++i) {
    const RigidSpec& b = scene.rigid_bodies[i];
    if (b.kinematic) set.set_kinematic(i);
    if (nonzero(b.force)) apply_scene_load("rigid_bodies", i, [&] { set.apply_force(i, converted<T>(b.force)); });
    if (nonzero(b.torque)) apply_scene_load("rigid_bodies", i, [&] { set.apply_torque(i, converted<T>(b.torque)); });
    apply_scene_load("rigid_bodies", i, [&] {
      if (b.damping) set.set_linear_damping(i, T(*b.damping));
      if (b.angular_damping) set.set_angular_damping(i, T(*b.angular_damping));
      if (b.gravity_factor) set.set_gravity_factor(i, T(*b.gravity_factor));
    });
  }
  set.keep_forces(true);
  for_each_generated_rigid_body(scene, add);
  return set;
}

template <class T>
ParticleSet<T> make_particles(const Scene& scene) {
  check_generated<T>(scene);
  auto v3 = [](const Vec3<double>& v) { return converted<T>(v); };
  ParticleSet<T> set;
  const std::size_t generated = scene.generate && !scene.generate->rigid ? scene.generate->count : 0;
  set.reserve(scene.particles.size() + generated);
  for (const BodySpec& b : scene.particles) {
    if (b.kinematic) {
      set.add_kinematic(v3(b.position), v3(b.velocity));
    } else {
      set.add(v3(b.position), v3(b.velocity), T(b.mass));
    }
  }
  for (std::size_t i = 0; i < scene.particles.size(); ++i) {
    const Vec3<double>& f = scene.particles[i].force;
    if (nonzero(f)) apply_scene_load("particles", i, [&] { set.apply_force(i, v3(f)); });
    apply_scene_load("particles", i, [&] {
      if (const auto& c = scene.particles[i].damping) set.set_linear_damping(i, T(*c));
      if (const auto& g = scene.particles[i].gravity_factor) set.set_gravity_factor(i, T(*g));
    });
  }
  set.keep_forces(true);
  add_generated_particles(scene, set);
  return set;
}

template <class T>
ForceModel<T> make_forces(const Scene& scene) {
  ForceModel<T> model;
  for (std::size_t i = 0; i < scene.forces.size(); ++i) {
    try {
      model.add(scene.forces[i]);
    } catch (const Error& e) {
      throw Error("forces[" + std::to_string(i) + "]: " + e.what());
    }
  }
  try {
    if (scene.nbody) model.add(*scene.nbody);
    // One network, checked once: each add would check every pair added before it again.
    if (scene.springs.size() == 1) model.add(scene.springs[0]);
    if (scene.springs.size() > 1) {
      Springs all;
      for (const Springs& network : scene.springs) all.pairs.insert(all.pairs.end(), network.pairs.begin(), network.pairs.end());
      model.add(std::move(all));
    }
    if (!scene.body_springs.springs.empty()) model.add(scene.body_springs);
  } catch (const Error& e) {
    throw Error(std::string("forces: ") + e.what());
  }
  return model;
}

template RigidBodySet<float> make_rigid_bodies<float>(const Scene&);
template RigidBodySet<double> make_rigid_bodies<double>(const Scene&);
template ParticleSet<float> make_particles<float>(const Scene&);
template ParticleSet<double> make_particles<double>(const Scene&);
template <class T>
EventOptions<T> make_events(const Scene& scene) {
  EventOptions<T> options;
  for (const EventSpec& e : scene.events) {
    Event<T> event;
    std::visit([&](const auto& kind) { event.kind = kind; }, e.kind);
    event.direction = e.direction;
    event.action = e.action;
    options.events.push_back(std::move(event));
  }
  return options;
}

template EventOptions<float> make_events<float>(const Scene&);
template EventOptions<double> make_events<double>(const Scene&);
template ForceModel<float> make_forces<float>(const Scene&);
template ForceModel<double> make_forces<double>(const Scene&);

}  // namespace kinema
