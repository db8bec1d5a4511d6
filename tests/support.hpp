#pragma once
// Helpers shared by the tests: one-body runs, state hashing, analytic error measures.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <cstring>
#include <vector>

#include "kinema/scenes.hpp"
#include "thread_pool.hpp"

namespace kinema::test {

// The ISA the physics tests run on: KINEMA_TEST_ISA when set (ctest runs the suite once
// per ISA), else the best one. Exits with 77 (ctest: skipped) when this CPU lacks it.
inline Isa test_isa() {
  static const Isa isa = [] {
    const char* name = std::getenv("KINEMA_TEST_ISA");
    if (name == nullptr) return Isa::automatic;
    const Isa requested = isa_by_name(name);
    if (!isa_available(requested)) {
      std::fprintf(stderr, "skipped: this CPU has no %s\n", name);
      std::exit(77);
    }
    return requested;
  }();
  return isa;
}

inline StepperOptions serial_options(Isa isa = test_isa()) {
  StepperOptions o;
  o.isa = isa;
  return on_calling_thread(o);
}

template <class T>
struct Snapshot {
  Vec3<double> x, v;
};

// Steps one body of mass m from (x0, v0) n times with step h; returns its final state.
template <class T>
Snapshot<T> run_one(const Method& method, const ForceModel<T>& forces, const Vec3<T>& x0,
                    const Vec3<T>& v0, T mass, T h, std::uint64_t n,
                    StepperOptions options = serial_options()) {
  ParticleSet<T> bodies;
  bodies.add(x0, v0, mass);
  Stepper<T> stepper(forces, method, options);
  stepper.advance(bodies, h, n);
  const auto x = bodies.position(0), v = bodies.velocity(0);
  return {{x[0], x[1], x[2]}, {v[0], v[1], v[2]}};
}

inline double distance(const Vec3<double>& a, const Vec3<double>& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                   (a[2] - b[2]) * (a[2] - b[2]));
}

// Least-squares slope of log(error) against log(h): the measured order of convergence.
inline double fitted_order(const std::vector<double>& h, const std::vector<double>& error) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = double(h.size());
  for (std::size_t i = 0; i < h.size(); ++i) {
    const double x = std::log(h[i]), y = std::log(error[i]);
    sx += x, sy += y, sxx += x * x, sxy += x * y;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// FNV-1a over every array of the set, padding included: equal hashes mean equal bits.
template <class T>
std::uint64_t state_hash(const ParticleSet<T>& b) {
  std::uint64_t hash = 1469598103934665603ull;
  for (const T* a : {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz(), b.inv_mass()}) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(a);
    for (std::size_t i = 0; i < b.padded_size() * sizeof(T); ++i) {
      hash = (hash ^ bytes[i]) * 1099511628211ull;
    }
  }
  return hash;
}

// The same over a rigid set: its centres, orientations and angular momenta.
template <class T>
std::uint64_t state_hash(const RigidBodySet<T>& b) {
  std::uint64_t hash = state_hash(b.centers());
  for (const T* a : {b.q(0), b.q(1), b.q(2), b.q(3), b.l(0), b.l(1), b.l(2)}) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(a);
    for (std::size_t i = 0; i < b.padded_size() * sizeof(T); ++i) hash = (hash ^ bytes[i]) * 1099511628211ull;
  }
  return hash;
}

// A reproducible cloud of bodies with a spread of masses, for determinism tests.
template <class T>
ParticleSet<T> cloud(std::size_t count, std::uint64_t seed = 3) {
  Scene scene;
  scene.generate = GenerateSpec{count, seed, {-2, -2, -2}, {2, 2, 2}, {-1, -1, -1}, {1, 1, 1}, 2};
  ParticleSet<T> set = make_particles<T>(scene);
  for (std::size_t i = 0; i < count; i += 7) set.set_velocity(i, {T(0.5), T(-1), T(2)});
  return set;
}

// The cloud's centres as rigid bodies, turning and tumbling, of many shapes and masses.
template <class T>
RigidBodySet<T> tumbling_cloud(std::size_t n) {
  RigidBodySet<T> set;
  const ParticleSet<T> centers = cloud<T>(n);
  for (std::size_t i = 0; i < n; ++i) {
    const T a = T(i % 17) / 17, b = T(i % 5) / 5;
    set.add({centers.position(i), centers.velocity(i), {1, a, b, T(0.3)}, {a, T(1), b},
             T(1) + a, {T(1) + a, T(2), T(2.5) - b}});
  }
  return set;
}

// Every built-in local term, with a central attractor off the cloud's centre.
template <class T>
ForceModel<T> all_local_terms(bool quadratic = true, bool central = true) {
  ForceModel<T> f;
  f.add(Gravity{{0.1, -9.81, 0.2}});
  f.add(LinearDrag{0.3});
  f.add(Spring{{0.5, -0.25, 1}, 2.5, 0.1});
  if (quadratic) f.add(QuadraticDrag{0.05});
  if (central) f.add(Central{{7, 3, -5}, 4});
  return f;
}

// Every local term and every rotational one (rigid bodies).
template <class T>
ForceModel<T> rotational_terms() {
  ForceModel<T> f = all_local_terms<T>();
  f.add(Torque{{0.1, 0.2, -0.3}}).add(AngularDrag{0.05}).add(PointForce{{0.5, 0, 0}, {0, 1, 0}});
  return f;
}

// hash(options, bodies) of one run is the same on every instruction set (serially, on
// `isa_bodies` bodies: the scalar path is slow) and on 2 and 3 threads of the TBB job system
// and of a host's pool (on `thread_bodies`: several blocks) as serially on the best one.
template <class Hash>
void check_same_bits_everywhere(Hash&& hash, std::size_t isa_bodies, std::size_t thread_bodies) {
  const std::uint64_t scalar = hash(serial_options(Isa::scalar), isa_bodies);
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    INFO("isa " << isa_name(isa));
    if (isa_available(isa)) CHECK(hash(serial_options(isa), isa_bodies) == scalar);
  }
  const std::uint64_t serial = hash(serial_options(best_isa()), thread_bodies);
  for (unsigned threads : {2u, 3u}) {
    INFO(threads << " threads");
    TbbJobSystem tbb(threads);
    ThreadPool pool(threads);
    StepperOptions o;
    o.inline_below = 0;
    o.jobs = &tbb;
    CHECK(hash(o, thread_bodies) == serial);
    o.jobs = &pool;
    CHECK(hash(o, thread_bodies) == serial);
  }
}

}  // namespace kinema::test
