#include "scene/scene_checks.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <string>

#include <sys/resource.h>
#include <unistd.h>

#include "core/text.hpp"
#include "forces/force_terms.hpp"
#include "kinema/error.hpp"
#include "kinema/methods.hpp"
#include "kinema/stepper.hpp"
#include "scene/networks.hpp"
#include "step/step_checks.hpp"

namespace kinema {
namespace {

// Arrays per body: px py pz vx vy vz inv_mass; rigid bodies add q (4), L (3) and the
// inverse principal moments (3).
constexpr double kParticleArrays = 7, kRigidArrays = 17;

std::string size_text(double bytes) {
  char text[32];
  if (bytes < double(1 << 30)) {
    std::snprintf(text, sizeof text, "%.0f MiB", bytes / double(1 << 20));
  } else {
    std::snprintf(text, sizeof text, "%.1f GiB", bytes / double(1 << 30));
  }
  return text;
}

template <class T>
bool holds(double x) {
  return std::isfinite(T(x));
}

template <class T>
bool holds(const Vec3<double>& v) {
  return holds<T>(v[0]) && holds<T>(v[1]) && holds<T>(v[2]);
}

double largest(const Vec3<double>& v) {
  return std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])});
}

std::string shown(const Vec3<double>& v) {
  char text[96];
  std::snprintf(text, sizeof text, "(%g, %g, %g)", v[0], v[1], v[2]);
  return text;
}

// Listed masses that T cannot invert (1e-50 is 0 in float), and positions, velocities and
// applied forces it cannot hold, named by their JSON path: a listed body's own, or that of
// the network generator that made it.
template <class T>
void check_listed_bodies(const Scene& scene) {
  const std::string type = type_name<T>();
  const Vec3<double> gravity = sum_terms(scene.forces).gravity;
  auto mass_fails = [](double mass) {
    const T inverse = T(1) / T(mass);
    return !(std::isfinite(inverse) && inverse > 0);
  };
  auto fail_mass = [&](const std::string& path, double mass) {
    char text[64];
    std::snprintf(text, sizeof text, "%g", mass);
    throw Error(printable(path + ".mass: " + text + " has no finite nonzero inverse in " + type));
  };
  for (std::size_t i = 0; i < scene.particles.size(); ++i) {
    const BodySpec& b = scene.particles[i];
    const Scene::Generated* g = generator_of(scene, i);
    const std::string path = g ? g->path : "particles[" + std::to_string(i) + "]";
    if (!b.kinematic && mass_fails(b.mass)) fail_mass(path, b.mass);
    if (!holds<T>(b.position)) {
      if (g) {
        throw Error(printable(g->path + ".spacing: its body " + std::to_string(i - g->first) + " lies at " +
                              shown(b.position) + ", beyond " + type));
      }
      throw Error(printable(path + ".position: " + shown(b.position) + " overflows " + type));
    }
    if (!holds<T>(b.velocity)) throw Error(printable(path + ".velocity: " + shown(b.velocity) + " overflows " + type));
    if (!holds<T>(b.force)) throw Error(printable(path + ".force: " + shown(b.force) + " overflows " + type));
    // The accelerations they give, as g: one that T cannot hold is refused, not stepped to inf.
    if (b.kinematic) continue;
    const Vec3<double> pushed{b.force[0] / b.mass, b.force[1] / b.mass, b.force[2] / b.mass};
    if (!holds<T>(pushed)) {
      throw Error(printable(path + ".force: " + shown(b.force) + " over the mass gives an acceleration that overflows " +
                            type));
    }
    const double factor = b.gravity_factor.value_or(1);
    if (!holds<T>(Vec3<double>{gravity[0] * factor, gravity[1] * factor, gravity[2] * factor})) {
      throw Error(printable(path + ".gravity_factor: " + shortest_text(factor) + " times the gravity " +
                            shown(gravity) + " overflows " + type));
    }
  }
  for (std::size_t i = 0; i < scene.rigid_bodies.size(); ++i) {
    if (mass_fails(scene.rigid_bodies[i].mass)) fail_mass("rigid_bodies[" + std::to_string(i) + "]", scene.rigid_bodies[i].mass);
  }
}

}  // namespace

template <class T>
void check_generated(const Scene& scene) {
  if (!scene.generate) return;
  const GenerateSpec& g = *scene.generate;
  const std::string type = type_name<T>();
  auto fail = [&](const std::string& key, const std::string& what) {
    throw Error(printable("generate." + key + ": " + what));
  };
  const double need = state_bytes<T>(scene), have = usable_memory_bytes();
  if (need > have) {
    fail("count", std::to_string(g.count) + (g.rigid ? " rigid bodies" : " particles") + " in " +
                      type + " need " + size_text(need) + " of state, more than the " + size_text(have) +
                      " this process may use");
  }
  const T inv_mass = T(1) / T(g.mass);
  if (!(std::isfinite(inv_mass) && inv_mass > 0)) {
    fail("mass", "has no finite nonzero inverse in " + type);
  }
  const std::pair<const char*, const Vec3<double>*> boxes[] = {
      {"position_min", &g.position_min}, {"position_max", &g.position_max},
      {"velocity_min", &g.velocity_min}, {"velocity_max", &g.velocity_max},
      {"angular_velocity_min", &g.angular_velocity_min},
      {"angular_velocity_max", &g.angular_velocity_max}};
  for (const auto& [key, box] : boxes) {
    if (!holds<T>(*box)) fail(key, "overflows " + type);
  }
  if (g.plummer_radius > 0) {
    if (!holds<T>(40 * g.plummer_radius)) fail("radius", "overflows " + type);
    // The speed at the centre, as the generator computes it (a radius whose square
    // underflows double makes it infinite).
    const double GM = (scene.nbody ? scene.nbody->G : 1) * g.mass * double(g.count);
    const double a = g.plummer_radius;
    if (!holds<T>(std::sqrt(2 * GM) / std::sqrt(std::sqrt(a * a)))) {
      char text[160];
      std::snprintf(text, sizeof text, "%g with G M = %g: the escape speed at the centre, sqrt(2 G M / radius), "
                    "overflows %s", a, GM, type.c_str());
      fail("radius", text);
    }
  }
  if (!g.rigid) return;
  for (int d = 0; d < 3; ++d) {
    const T inverse = T(1) / T(g.inertia[d]);
    if (!(std::isfinite(inverse) && inverse > 0)) fail("inertia", "a moment has no finite inverse in " + type);
  }
  // |L| <= max moment x |omega| <= max moment x sqrt(3) x largest component.
  const double omega = std::max(largest(g.angular_velocity_min), largest(g.angular_velocity_max));
  if (!holds<T>(largest(g.inertia) * std::sqrt(3.0) * omega)) {
    fail("angular_velocity_max", "the angular momentum it gives overflows " + type);
  }
}

double usable_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  double bytes = pages > 0 && page > 0 ? double(pages) * double(page) : HUGE_VAL;
  rlimit limit{};
  if (::getrlimit(RLIMIT_AS, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY) {
    bytes = std::min(bytes, double(limit.rlim_cur));
  }
  // cgroup v2 ("max" when unlimited, then the read fails and nothing changes).
  std::ifstream cgroup("/sys/fs/cgroup/memory.max");
  double cgroup_bytes = 0;
  if (cgroup >> cgroup_bytes && cgroup_bytes > 0) bytes = std::min(bytes, cgroup_bytes);
  return bytes;
}

template <class T>
double state_bytes(const Scene& scene) {
  const bool rigid = scene.generate && scene.generate->rigid;
  const double generated = scene.generate ? double(scene.generate->count) : 0;
  const double particles = double(scene.particles.size()) + (rigid ? 0 : generated);
  const double rigid_bodies = double(scene.rigid_bodies.size()) + (rigid ? generated : 0);
  return (particles * kParticleArrays + rigid_bodies * kRigidArrays) * double(sizeof(T));
}

double evaluation_cost(const Scene& scene) {
  const double bodies = double(scene.particles.size() + scene.rigid_bodies.size()) +
                        (scene.generate ? double(scene.generate->count) : 0);
  double springs = 0;
  for (const Springs& network : scene.springs) springs += double(network.pairs.size());
  // A body spring's two ends each turn both its points: about 8 body-evaluations each.
  springs += 16 * double(scene.body_springs.springs.size());
  return bodies + springs + (scene.nbody ? bodies * bodies / 2 : 0);
}

template <class T>
RunBytes run_bytes(const Scene& scene) {
  // Calibrated on peak resident sizes of `kinema run` (grids of 256^2 to 4 x 1024^2 bodies,
  // 4M generated particles), rounded up: copies of the state for the run, listed bodies as
  // parsed, and for coupled scenes the stiffness estimate's Krylov vectors (at most
  // 512 MiB), the stages' scratch in T and in double, and per spring the model's copies and
  // the network's layout in both.
  constexpr double kListedBody = 100, kEstimateVectors = 21 * 6 * 8, kEstimateCap = double(512 << 20);
  constexpr double kDoubleProbe = (9 + 7) * 8, kSpringCopies = 4 * sizeof(SpringPair);
  constexpr double kMargin = 1.2;
  RunBytes r;
  r.state = 3 * state_bytes<T>(scene) + kListedBody * double(scene.particles.size() + scene.rigid_bodies.size());
  const bool coupled = scene.nbody || !scene.springs.empty() || !scene.body_springs.springs.empty();
  const Method& method = scene.method == "auto" ? rk6 : method_by_name(scene.method);
  // A rigid body's stage state is about twice a particle's.
  const double n = double(scene.particles.size()) + 2 * double(scene.rigid_bodies.size()) +
                   (scene.generate ? double(scene.generate->count) * (scene.generate->rigid ? 2 : 1) : 0);
  const double stages = double(std::max(method.evaluations(), 1));
  if (!coupled && std::ranges::find(staged_methods, &method) != staged_methods.end()) {
    // No fused kernel (bs3, dopri5, rk6): local terms too take stages kept in memory (peak
    // resident sizes at 2M float particles: 22, 42 and 48 scalars a body more than rk4).
    r.scratch = n * (stages * 6 + 9) * sizeof(T);
  }
  if (coupled) {
    r.scratch = std::min(kEstimateVectors * n, kEstimateCap) + n * (kDoubleProbe + (stages * 9 + 9) * sizeof(T));
    double pairs = 0;
    for (const Springs& network : scene.springs) pairs += double(network.pairs.size());
    pairs += 2 * double(scene.body_springs.springs.size());
    r.springs = pairs * (kSpringCopies + 2 * 1.5 * (4 + 3 * sizeof(T)) + 2 * 1.5 * (4 + 3 * sizeof(double)));
    if (method.kind == MethodKind::linearly_implicit) r.springs += pairs * 2 * 1.5 * 7 * sizeof(T);  // 7 a slot
  }
  if (scene.method != "auto" && method_by_name(scene.method).kind == MethodKind::linearly_implicit) {
    // ImplicitPath: 40 arrays a body, its own accelerations probe's 9 besides.
    const double n = double(scene.particles.size()) + (scene.generate ? double(scene.generate->count) : 0);
    r.scratch += n * 49 * sizeof(T);
  }
  r.state *= kMargin, r.scratch *= kMargin, r.springs *= kMargin;
  return r;
}

template <class T>
void check_scene(const Scene& scene) {
  check_listed_bodies<T>(scene);
  check_generated<T>(scene);
  const RunBytes need = run_bytes<T>(scene);
  const double have = usable_memory_bytes();
  if (need.total() > have) {
    throw Error("the scene needs about " + size_text(need.total()) + " to run (" + size_text(need.state) + " for its bodies, " +
                size_text(need.springs) + " for its springs, " + size_text(need.scratch) +
                " for the stiffness estimate and the stages), more than the " + size_text(have) + " this process may use");
  }
  if (!scene.events.empty() && mixed_bodies(scene)) {
    throw Error("events: events watch bodies of one kind; the scene has particles and rigid bodies");
  }
  const ForceModel<T> forces = make_forces<T>(scene);
  // Lowering the forces to T checks their sums; auto picks its own dt later.
  const Method& method = scene.method == "auto" ? rk4 : method_by_name(scene.method);
  const bool rigid = !scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid);
  if (method.kind == MethodKind::linearly_implicit && (rigid || !scene.events.empty())) {
    throw Error("method: " + std::string(method.name) + " (implicit) steps particles without events: this scene has " +
                (rigid ? "rigid bodies" : "events"));
  }
  std::optional<Stepper<T>> stepper;
  try {
    stepper.emplace(forces, method, on_calling_thread());
  } catch (const Error& e) {
    throw Error(std::string("forces: ") + e.what());
  }
  if (scene.method == "auto") return;
  try {
    // Under error control dt is the output interval, not a step: its steps are checked as
    // advance_to takes them (and shrunk where their sums would overflow).
    if (scene.rtol || scene.atol) {
      check_step_positive(T(scene.dt));
    } else {
      stepper->check_step_size(T(scene.dt));
    }
  } catch (const Error& e) {
    throw Error(std::string("dt: ") + e.what());
  }
}

template void check_generated<float>(const Scene&);
template void check_generated<double>(const Scene&);
template void check_scene<float>(const Scene&);
template void check_scene<double>(const Scene&);
template double state_bytes<float>(const Scene&);
template RunBytes run_bytes<float>(const Scene&);
template RunBytes run_bytes<double>(const Scene&);
template double state_bytes<double>(const Scene&);

bool takes_implicit_methods(const Scene& scene) {
  const bool rigid = !scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid);
  return !scene.springs.empty() && !rigid && scene.events.empty();
}

const Scene::Generated* generator_of(const Scene& scene, std::size_t i) {
  for (const Scene::Generated& g : scene.generated_particles) {
    if (i >= g.first && i - g.first < g.count) return &g;
  }
  return nullptr;
}

}  // namespace kinema
