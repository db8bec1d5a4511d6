#include "stress_scene.hpp"

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <utility>
#include <variant>

namespace kinema::cli {
namespace {

// splitmix64: the same numbers on every platform, from exact integer and double operations.
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform(double lo, double hi) { return lo + (hi - lo) * (double(next() >> 11) * 0x1p-53); }
  Vec3<double> point(double lo, double hi) { return {uniform(lo, hi), uniform(lo, hi), uniform(lo, hi)}; }

 private:
  std::uint64_t state_;
};

template <class T>
bool energy_conserved_by(const ForceModel<T>& f, bool rigid) {
  if (!f.callbacks().empty() || !f.coupled_terms().empty()) return false;
  for (const LocalTerm& term : f.local_terms()) {
    const bool conservative = std::visit(
        [&](const auto& t) {
          using Term = std::decay_t<decltype(t)>;
          if constexpr (std::is_same_v<Term, Gravity> || std::is_same_v<Term, Central>) return true;
          if constexpr (std::is_same_v<Term, Spring>) return t.damping == 0;
          if constexpr (std::is_same_v<Term, PointSpring>) return !rigid || t.damping == 0;
          // Rotational terms do not act on particles.
          if constexpr (std::is_same_v<Term, Torque> || std::is_same_v<Term, AngularDrag> ||
                        std::is_same_v<Term, PointForce>) {
            return !rigid;
          }
          return false;  // drag
        },
        term);
    if (!conservative) return false;
  }
  return std::all_of(f.springs().begin(), f.springs().end(), [](const SpringPair& p) { return p.damping == 0; }) &&
         std::all_of(f.body_springs().begin(), f.body_springs().end(), [](const BodySpring& s) { return s.damping == 0; });
}

template <class T>
bool momentum_conserved_by(const ForceModel<T>& f) {
  return f.local_terms().empty() && f.callbacks().empty() && f.coupled_terms().empty() &&
         (f.nbody() || !f.springs().empty());
}

template <class Set>
double sum_of_m_v(const Set& b) {
  double sum = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.inv_mass()[i] == 0) continue;
    const auto v = b.velocity(i);
    sum += std::sqrt(double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2]) / b.inv_mass()[i];
  }
  return sum;
}

// How the built-in scene divides its bodies.
struct Split {
  std::size_t cluster, network_side, spinning, free, field;
};

Split split(std::uint64_t n) {
  Split s{};
  s.cluster = std::size_t(std::min<std::uint64_t>(n / 16, 2048));
  if (s.cluster < 2) s.cluster = 0;
  s.network_side = std::size_t(std::sqrt(0.3 * double(n)));
  if (s.network_side < 2) s.network_side = 0;
  s.spinning = n / 10, s.free = n / 10;
  s.field = std::size_t(n - s.cluster - s.network_side * s.network_side - s.spinning - s.free);
  return s;
}

// Generated bodies from boxes, as a scene's "generate" makes them.
GenerateSpec boxes(std::size_t count, std::uint64_t seed, double extent, double speed) {
  GenerateSpec g;
  g.count = count, g.seed = seed;
  g.position_min = {-extent, -extent, -extent}, g.position_max = {extent, extent, extent};
  g.velocity_min = {-speed, -speed, -speed}, g.velocity_max = {speed, speed, speed};
  return g;
}

// Every local term. Bodies stay near their anchor; the attractors sit far outside the box.
template <class T>
ForceModel<T> field_forces(Random& r) {
  ForceModel<T> f;
  f.add(Gravity{{r.uniform(-1, 1), -r.uniform(8, 12), r.uniform(-1, 1)}});
  f.add(LinearDrag{r.uniform(0.01, 0.1)});
  f.add(QuadraticDrag{r.uniform(0.001, 0.01)});
  f.add(Spring{r.point(-5, 5), r.uniform(0.5, 2), r.uniform(0, 0.2)});
  f.add(Central{{r.uniform(500, 1000), r.uniform(-100, 100), 0}, r.uniform(100, 1000)});
  f.add(Central{{0, r.uniform(-100, 100), -r.uniform(500, 1000)}, r.uniform(100, 1000)});
  return f;
}

// A free square sheet: structural and shear springs, no damping, a small random drift.
template <class T>
std::pair<ParticleSet<T>, ForceModel<T>> network(std::size_t side, Random& r) {
  constexpr double kSpacing = 0.1, kStiffness = 100;
  ParticleSet<T> b;
  b.reserve(side * side);
  for (std::size_t i = 0; i < side; ++i) {
    for (std::size_t j = 0; j < side; ++j) {
      const auto v = r.point(-0.05, 0.05);
      b.add({T(double(i) * kSpacing), T(20), T(double(j) * kSpacing)}, {T(v[0]), T(v[1]), T(v[2])}, T(1));
    }
  }
  Springs s;
  s.pairs.reserve(4 * side * side);
  const auto at = [&](std::size_t i, std::size_t j) { return std::uint32_t(i * side + j); };
  const double diagonal = kSpacing * std::sqrt(2.0);
  for (std::size_t i = 0; i < side; ++i) {
    for (std::size_t j = 0; j < side; ++j) {
      if (j + 1 < side) s.pairs.push_back({at(i, j), at(i, j + 1), kSpacing, kStiffness, 0});
      if (i + 1 < side) s.pairs.push_back({at(i, j), at(i + 1, j), kSpacing, kStiffness, 0});
      if (i + 1 < side && j + 1 < side) {
        s.pairs.push_back({at(i, j), at(i + 1, j + 1), diagonal, kStiffness, 0});
        s.pairs.push_back({at(i, j + 1), at(i + 1, j), diagonal, kStiffness, 0});
      }
    }
  }
  ForceModel<T> f;
  f.add(std::move(s));
  return {std::move(b), std::move(f)};
}

// A Plummer sphere of total mass 1 under softened gravity (G = 1).
template <class T>
std::pair<ParticleSet<T>, ForceModel<T>> cluster(std::size_t count, std::uint64_t seed) {
  Scene scene;
  scene.nbody = NBody{1, 0.05};
  scene.generate = GenerateSpec{};
  scene.generate->count = count, scene.generate->seed = seed;
  scene.generate->mass = 1.0 / double(count);
  scene.generate->plummer_radius = 1;
  ForceModel<T> f;
  f.add(*scene.nbody);
  return {make_particles<T>(scene), std::move(f)};
}

template <class T>
RigidBodySet<T> rigid_boxes(std::size_t count, std::uint64_t seed, Random& r) {
  Scene scene;
  scene.generate = boxes(count, seed, 20, 2);
  scene.generate->rigid = true;
  scene.generate->inertia = {r.uniform(0.5, 1), r.uniform(1, 2), r.uniform(2, 3)};
  scene.generate->angular_velocity_min = {-3, -3, -3}, scene.generate->angular_velocity_max = {3, 3, 3};
  return make_rigid_bodies<T>(scene);
}

// Every local and rotational term: driven and damped spin.
template <class T>
ForceModel<T> spinning_forces(Random& r) {
  ForceModel<T> f = field_forces<T>(r);
  f.add(Torque{r.point(-1, 1)});
  f.add(AngularDrag{r.uniform(0.05, 0.2)});
  f.add(PointForce{r.point(-0.5, 0.5), r.point(-2, 2)});
  return f;
}

// Conservative: free spin, gravity and an undamped anchor.
template <class T>
ForceModel<T> free_forces(Random& r) {
  ForceModel<T> f;
  f.add(Gravity{{0, -9.81, 0}});
  f.add(Spring{r.point(-5, 5), r.uniform(0.5, 2), 0});
  return f;
}

}  // namespace

template <class T>
StressGroup<T>::StressGroup(std::string name, ParticleSet<T> bodies, ForceModel<T> forces,
                            const Method& method, const StepperOptions& options)
    : name_(std::move(name)), rigid_(false), conserves_energy_(energy_conserved_by(forces, false)),
      conserves_momentum_(momentum_conserved_by(forces)), particles_(std::move(bodies)),
      stepper_(std::move(forces), method, options) {}

template <class T>
StressGroup<T>::StressGroup(std::string name, RigidBodySet<T> bodies, ForceModel<T> forces,
                            const Method& method, const StepperOptions& options)
    : name_(std::move(name)), rigid_(true), conserves_energy_(energy_conserved_by(forces, true)),
      conserves_momentum_(momentum_conserved_by(forces)), rigid_bodies_(std::move(bodies)),
      stepper_(std::move(forces), method, options) {}

template <class T>
void StressGroup<T>::advance(T h, std::uint64_t steps) {
  if (rigid_) return stepper_.advance(rigid_bodies_, h, steps);
  stepper_.advance(particles_, h, steps);
}

template <class T>
void StressGroup<T>::save(CheckpointWriter& out) const {
  if (rigid_) return out.add(rigid_bodies_, stepper_);
  out.add(particles_, stepper_);
}

template <class T>
void StressGroup<T>::restore(const CheckpointReader& in, std::size_t k) {
  const std::size_t before = size();
  const auto check_size = [&](std::size_t restored) {
    if (restored != before) {
      throw Error("checkpoint record " + std::to_string(k) + " holds " + std::to_string(restored) + " bodies, group " +
                  name_ + " " + std::to_string(before));
    }
  };
  if (rigid_) {
    RigidBodySet<T> b = in.rigid_bodies(k, stepper_);
    check_size(b.size());
    stepper_.set_clock(in.clock(k));
    rigid_bodies_ = std::move(b);
  } else {
    ParticleSet<T> b = in.particles(k, stepper_);
    check_size(b.size());
    stepper_.set_clock(in.clock(k));
    particles_ = std::move(b);
  }
}

template <class T>
double StressGroup<T>::energy() const {
  if (rigid_) return kinema::energy(rigid_bodies_, stepper_.forces()).total();
  return kinema::energy(particles_, stepper_.forces()).total();
}

template <class T>
Vec3<double> StressGroup<T>::momentum() const {
  return kinema::momentum(rigid_ ? rigid_bodies_.centers() : particles_);
}

template <class T>
double StressGroup<T>::momentum_scale() const {
  return sum_of_m_v(rigid_ ? rigid_bodies_.centers() : particles_);
}

template <class T>
std::optional<NonFinite> StressGroup<T>::first_non_finite() const {
  return rigid_ ? kinema::first_non_finite(rigid_bodies_) : kinema::first_non_finite(particles_);
}

template <class T>
std::size_t StressGroup<T>::state_bytes() const {
  // Particles: position, velocity, inv_mass; rigid bodies add q, L and the inverse moments.
  const std::size_t arrays = rigid_ ? 7 + 4 + 3 + 3 : 7;
  const std::size_t capacity = rigid_ ? rigid_bodies_.centers().capacity() : particles_.capacity();
  return arrays * capacity * sizeof(T) + stepper_.forces().springs().size() * sizeof(SpringPair);
}

template <class T>
std::vector<StressGroup<T>> random_stress_groups(std::uint64_t bodies, std::uint64_t seed,
                                                 const Method& method, const StepperOptions& options) {
  const Split s = split(std::max<std::uint64_t>(bodies, 1));
  Random r(seed);
  std::vector<StressGroup<T>> groups;
  groups.reserve(5);
  if (s.field > 0) {
    Scene scene;
    scene.generate = boxes(s.field, r.next(), 10, 5);
    groups.emplace_back("field", make_particles<T>(scene), field_forces<T>(r), method, options);
  }
  if (s.network_side > 0) {
    auto [b, f] = network<T>(s.network_side, r);
    groups.emplace_back("network", std::move(b), std::move(f), method, options);
  }
  if (s.cluster > 0) {
    auto [b, f] = cluster<T>(s.cluster, r.next());
    groups.emplace_back("cluster", std::move(b), std::move(f), method, options);
  }
  if (s.spinning > 0) {
    RigidBodySet<T> b = rigid_boxes<T>(s.spinning, r.next(), r);
    groups.emplace_back("spinning", std::move(b), spinning_forces<T>(r), method, options);
  }
  if (s.free > 0) {
    RigidBodySet<T> b = rigid_boxes<T>(s.free, r.next(), r);
    groups.emplace_back("free_rigid", std::move(b), free_forces<T>(r), method, options);
  }
  return groups;
}

template <class T>
std::vector<StressGroup<T>> scene_stress_groups(const Scene& scene, const Method& method,
                                                const StepperOptions& options) {
  std::vector<StressGroup<T>> groups;
  ParticleSet<T> particles = make_particles<T>(scene);
  if (particles.size() > 0) {
    groups.emplace_back("particles", std::move(particles), make_forces<T>(scene), method, options);
  }
  RigidBodySet<T> rigid = make_rigid_bodies<T>(scene);
  if (rigid.size() > 0) {
    groups.emplace_back("rigid_bodies", std::move(rigid), make_forces<T>(scene), method, options);
  }
  return groups;
}

template class StressGroup<float>;
template class StressGroup<double>;
template std::vector<StressGroup<float>> random_stress_groups(std::uint64_t, std::uint64_t, const Method&,
                                                              const StepperOptions&);
template std::vector<StressGroup<double>> random_stress_groups(std::uint64_t, std::uint64_t, const Method&,
                                                               const StepperOptions&);
template std::vector<StressGroup<float>> scene_stress_groups(const Scene&, const Method&, const StepperOptions&);
template std::vector<StressGroup<double>> scene_stress_groups(const Scene&, const Method&, const StepperOptions&);

}  // namespace kinema::cli
