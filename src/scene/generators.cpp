#include "scene/generators.hpp"

#include <cmath>
#include <numbers>
#include <random>

#include "scene/angular_momentum.hpp"

namespace kinema {
namespace {

// Uniform in [lo, hi] from the top 53 bits of a 64-bit Mersenne Twister: the same numbers
// on every platform (std::uniform_real_distribution is implementation-defined).
double uniform(std::mt19937_64& rng, double lo, double hi) {
  const double u = double(rng() >> 11) * 0x1.0p-53;
  return lo + (hi - lo) * u;
}

// A uniformly random rotation (Shoemake, "Uniform random rotations", Graphics Gems III). Its
// sines and cosines come from libm: generated rigid bodies may differ in the last bits
// between C libraries.
Quat<double> random_orientation(std::mt19937_64& rng) {
  const double u1 = uniform(rng, 0, 1), u2 = uniform(rng, 0, 2 * std::numbers::pi),
               u3 = uniform(rng, 0, 2 * std::numbers::pi);
  const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
  return {b * std::cos(u3), a * std::sin(u2), a * std::cos(u2), b * std::sin(u3)};
}

// A uniformly random direction (Marsaglia's method), and the Plummer sampling below, use
// only exactly rounded operations (+ - * / sqrt): the same bodies on every platform.
Vec3<double> random_direction(std::mt19937_64& rng) {
  double u = 0, v = 0, s = 2;
  while (s >= 1 || s == 0) u = uniform(rng, -1, 1), v = uniform(rng, -1, 1), s = u * u + v * v;
  const double scale = 2 * std::sqrt(1 - s);
  return {u * scale, v * scale, 1 - 2 * s};
}

// One body of a Plummer sphere (scale a, total mass M), positions cut at 20 a. The mass
// inside r is M X^(3/2) with X = r^2 / (r^2 + a^2); X, whose density is proportional to
// sqrt(X), comes by rejection, then r = a sqrt(X / (1 - X)). The speed is q times the escape
// speed sqrt(2 G M) (r^2 + a^2)^(-1/4), q by rejection from g(q) = q^2 (1 - q^2)^(7/2)
// (Aarseth, Henon and Wielen, 1974; g < 0.1).
void plummer_body(std::mt19937_64& rng, double a, double GM, Vec3<double>& x, Vec3<double>& v) {
  double r = INFINITY;
  while (!(r <= 20 * a)) {
    double X = 0, w = 1;
    while (w * w > X) X = uniform(rng, 0, 1), w = uniform(rng, 0, 1);
    r = a * std::sqrt(X / (1 - X));
  }
  double q = 0, g = 1;
  for (double s = 0; g > q * q * s * s * s * std::sqrt(s);) {
    q = uniform(rng, 0, 1), g = uniform(rng, 0, 0.1), s = 1 - q * q;
  }
  const double speed = q * std::sqrt(2 * GM) / std::sqrt(std::sqrt(r * r + a * a));
  const Vec3<double> along = random_direction(rng), heading = random_direction(rng);
  for (int d = 0; d < 3; ++d) x[d] = r * along[d], v[d] = speed * heading[d];
}

// The generated bodies of a Plummer scene, moved so their centre of mass is at rest at the
// origin: a first pass finds the means, a second one, from the same seed, adds the bodies.
template <class T>
void add_plummer(const Scene& scene, ParticleSet<T>& set) {
  const GenerateSpec& g = *scene.generate;
  const double GM = (scene.nbody ? scene.nbody->G : 1) * g.mass * double(g.count);
  Vec3<double> x, v, mean_x{}, mean_v{};
  std::mt19937_64 rng(g.seed);
  for (std::size_t i = 0; i < g.count; ++i) {
    plummer_body(rng, g.plummer_radius, GM, x, v);
    for (int d = 0; d < 3; ++d) mean_x[d] += x[d] / double(g.count), mean_v[d] += v[d] / double(g.count);
  }
  rng.seed(g.seed);
  for (std::size_t i = 0; i < g.count; ++i) {
    plummer_body(rng, g.plummer_radius, GM, x, v);
    Vec3<T> p, u;
    for (int d = 0; d < 3; ++d) p[d] = T(x[d] - mean_x[d]), u[d] = T(v[d] - mean_v[d]);
    set.add(p, u, T(g.mass));
  }
}

}  // namespace

template <class T>
void add_generated_particles(const Scene& scene, ParticleSet<T>& set) {
  if (!scene.generate || scene.generate->rigid || scene.generate->count == 0) return;
  if (scene.generate->plummer_radius > 0) return add_plummer(scene, set);
  const GenerateSpec& g = *scene.generate;
  std::mt19937_64 rng(g.seed);
  for (std::size_t i = 0; i < g.count; ++i) {
    Vec3<T> p, v;
    for (int d = 0; d < 3; ++d) p[d] = T(uniform(rng, g.position_min[d], g.position_max[d]));
    for (int d = 0; d < 3; ++d) v[d] = T(uniform(rng, g.velocity_min[d], g.velocity_max[d]));
    set.add(p, v, T(g.mass));
  }
}

void for_each_generated_rigid_body(const Scene& scene, const std::function<void(const RigidSpec&)>& add) {
  if (!scene.generate || !scene.generate->rigid) return;
  const GenerateSpec& g = *scene.generate;
  std::mt19937_64 rng(g.seed);
  for (std::size_t i = 0; i < g.count; ++i) {
    RigidSpec b;
    for (int d = 0; d < 3; ++d) b.position[d] = uniform(rng, g.position_min[d], g.position_max[d]);
    for (int d = 0; d < 3; ++d) b.velocity[d] = uniform(rng, g.velocity_min[d], g.velocity_max[d]);
    Vec3<double> omega;
    for (int d = 0; d < 3; ++d) {
      omega[d] = uniform(rng, g.angular_velocity_min[d], g.angular_velocity_max[d]);
    }
    b.orientation = random_orientation(rng);
    b.mass = g.mass;
    b.inertia = g.inertia;
    b.angular_momentum = momentum_from_velocity(b.orientation, b.inertia, omega);
    add(b);
  }
}

template void add_generated_particles(const Scene&, ParticleSet<float>&);
template void add_generated_particles(const Scene&, ParticleSet<double>&);

}  // namespace kinema
