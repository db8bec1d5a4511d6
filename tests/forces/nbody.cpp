// N-body gravity: the kernel against a plain loop, the fast variant's error, the two-body
// Kepler orbit, conservation of momentum, rk4's order on the energy error, and bit-identical
// results everywhere.
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <random>

#include "kernels/kernels.hpp"
#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

// A reproducible cluster: positions in a unit ball-ish box, masses from 0.5 to 2, small
// velocities. Every 37th body is kinematic (no mass: neither attracts nor moves).
template <class T>
ParticleSet<T> cluster(std::size_t n, bool kinematic = false, std::uint64_t seed = 5) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> pos(-1, 1), vel(-0.2, 0.2), mass(0.5, 2);
  ParticleSet<T> set;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<T> x{T(pos(rng)), T(pos(rng)), T(pos(rng))}, v{T(vel(rng)), T(vel(rng)), T(vel(rng))};
    if (kinematic && i % 37 == 0) {
      set.add_kinematic(x, v);
    } else {
      set.add(x, v, T(mass(rng)));
    }
  }
  return set;
}

// The kernel's sums over a whole set, in calls of `targets` bodies (a multiple of every
// SIMD width; the stepper's calls are blocks), with stage scale 1.
template <class T>
std::vector<T> kernel_sums(const ParticleSet<T>& b, Isa isa, T G, T eps2, bool fast = false,
                           std::size_t targets = kBlockBodies) {
  const std::size_t n = b.padded_size();
  AlignedArray<T> acc(3 * n);  // the kernels' stores are aligned
  kernels::NBodyJob<T> job{{b.px(), b.py(), b.pz()}, b.inv_mass(), n, eps2, G,
                           {acc.data(), acc.data() + n, acc.data() + 2 * n}, fast};
  const auto& table = kernels::kernel_table<T>(isa);
  for (std::size_t begin = 0; begin < n; begin += targets) {
    table.nbody(job, begin, std::min(n, begin + targets));
  }
  return {acc.data(), acc.data() + 3 * n};
}

// The same sums as a plain loop over (i, j) in T, with the kernel's operations in its
// order: the kernel must give these bits.
template <class T>
std::vector<T> plain_sums(const ParticleSet<T>& b, T G, T eps2) {
  const std::size_t n = b.padded_size();
  std::vector<T> acc(3 * n, T(0));
  const T* x[3] = {b.px(), b.py(), b.pz()};
  for (std::size_t i = 0; i < n; ++i) {
    if (b.inv_mass()[i] == 0) continue;
    T a[3] = {0, 0, 0};
    for (std::size_t j = 0; j < n; ++j) {
      if (b.inv_mass()[j] == 0) continue;  // massless: no source
      const T m = T(1) / b.inv_mass()[j];
      T d[3];
      for (int k = 0; k < 3; ++k) d[k] = x[k][j] - x[k][i];
      const T d2 = std::fma(d[0], d[0], std::fma(d[1], d[1], d[2] * d[2])), r2 = d2 + eps2;
      const T s = d2 != 0 ? m / (r2 * std::sqrt(r2)) : T(0);
      for (int k = 0; k < 3; ++k) a[k] = std::fma(s, d[k], a[k]);
    }
    for (int k = 0; k < 3; ++k) acc[k * n + i] = std::fma(G, a[k], T(0));
  }
  return acc;
}

template <class T>
void check_kernel_bits() {
  const ParticleSet<T> b = cluster<T>(1500, true);  // two blocks, the last one short
  const T G = T(0.75), eps2 = T(1e-4);
  const std::vector<T> plain = plain_sums(b, G, eps2);
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    INFO("isa " << isa_name(isa));
    CHECK(kernel_sums(b, isa, G, eps2) == plain);
  }
}

}  // namespace

TEST_CASE("nbody: every instruction set gives the bits of a plain loop in the same order", "[coupled]") {
  check_kernel_bits<float>();
  check_kernel_bits<double>();
}

TEST_CASE("nbody: the sums are the softened Newtonian accelerations", "[nbody]") {
  const ParticleSet<double> b = cluster<double>(1500, true);
  const double eps2 = 1e-4;
  const std::vector<double> got = kernel_sums(b, test::test_isa(), 1.0, eps2);
  const std::size_t n = b.padded_size();
  double worst = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.inv_mass()[i] == 0) continue;
    long double a[3] = {0, 0, 0}, scale = 0;
    for (std::size_t j = 0; j < b.size(); ++j) {
      if (b.inv_mass()[j] == 0 || j == i) continue;
      const long double m = 1.0L / b.inv_mass()[j];
      const long double dx = (long double)b.px()[j] - b.px()[i], dy = (long double)b.py()[j] - b.py()[i],
                        dz = (long double)b.pz()[j] - b.pz()[i];
      const long double r2 = dx * dx + dy * dy + dz * dz + eps2, s = m / (r2 * std::sqrt(r2));
      a[0] += s * dx, a[1] += s * dy, a[2] += s * dz;
      scale += s * std::sqrt(r2);  // sum of |terms|: what the round-off scales with
    }
    for (int k = 0; k < 3; ++k) {
      const double error = std::abs(double(got[k * n + i] - a[k])) / double(scale);
      worst = std::max(worst, error);
    }
  }
  // Against a long double reference: round-off of a 1500-term sum, relative to the sum of
  // magnitudes (the sum itself may cancel). A wrong power of r or a lost softening is O(1).
  CHECK(worst < 1e-13);
}

namespace {

// Two bodies on an ellipse of semi-major axis a and eccentricity e about their centre of
// mass, starting at periapsis: returns the set and the orbital period.
ParticleSet<double> binary(double m1, double m2, double a, double e, double& period) {
  const double mu = m1 + m2;  // G = 1
  const double r = a * (1 - e), speed = std::sqrt(mu * (1 + e) / r);  // relative, at periapsis
  period = 2 * std::numbers::pi * std::sqrt(a * a * a / mu);
  ParticleSet<double> b;
  b.add({-r * m2 / mu, 0, 0}, {0, -speed * m2 / mu, 0}, m1);
  b.add({r * m1 / mu, 0, 0}, {0, speed * m1 / mu, 0}, m2);
  return b;
}

double separation(const ParticleSet<double>& b) {
  return test::distance({b.px()[0], b.py()[0], b.pz()[0]}, {b.px()[1], b.py()[1], b.pz()[1]});
}

Vec3<double> centre_of_mass(const ParticleSet<double>& b) {
  Vec3<double> c{};
  double total = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double m = 1 / b.inv_mass()[i];
    total += m;
    for (int d = 0; d < 3; ++d) c[d] += m * b.position(i)[d];
  }
  for (double& x : c) x /= total;
  return c;
}

}  // namespace

TEST_CASE("nbody: two bodies follow the Kepler ellipse, the centre of mass stays put", "[nbody]") {
  const double a = 1.5, e = 0.6;
  double period = 0;
  ParticleSet<double> b = binary(1.0, 0.25, a, e, period);
  ForceModel<double> f;
  f.add(NBody{1.0, 0.0});
  Stepper<double> s(f, rk4, test::serial_options());
  const int steps = 4000;
  const double h = period / steps;
  double closest = separation(b), farthest = closest;
  for (int k = 0; k < steps; ++k) {
    s.step(b, h);
    closest = std::min(closest, separation(b)), farthest = std::max(farthest, separation(b));
    const Vec3<double> c = centre_of_mass(b);
    REQUIRE(std::hypot(c[0], c[1], c[2]) < 1e-13);
  }
  // Periapsis a (1 - e) and apoapsis a (1 + e) (the apoapsis falls on a step: steps even).
  CHECK(closest == Approx(a * (1 - e)).epsilon(1e-12));
  CHECK(farthest == Approx(a * (1 + e)).epsilon(1e-7));
  // After one period, back at periapsis.
  CHECK(b.px()[1] - b.px()[0] == Approx(a * (1 - e)).epsilon(1e-7));
  CHECK(std::abs(b.py()[1] - b.py()[0]) < 1e-6);
}

TEST_CASE("nbody: every method conserves a cluster's momentum to round-off", "[nbody]") {
  ForceModel<double> f;
  f.add(NBody{1.0, 0.05});
  for (const Method* m : builtin_methods) {
    INFO("method " << m->name);
    ParticleSet<double> b = cluster<double>(64);
    const Vec3<double> p0 = momentum(b);
    double scale = 0;  // sum of m |v|: what the round-off scales with
    Stepper<double> s(f, *m, test::serial_options());
    for (int k = 0; k < 200; ++k) {
      s.step(b, 1e-3);
      for (std::size_t i = 0; i < b.size(); ++i) {
        scale = std::max(scale, test::distance(b.velocity(i), {0, 0, 0}) / b.inv_mass()[i]);
      }
    }
    const Vec3<double> p = momentum(b);
    CHECK(test::distance(p, p0) < 1e-13 * scale * double(b.size()));
    CHECK(test::distance(p, p0) > 0);  // not trivially: the bodies did move each other
  }
}

TEST_CASE("nbody: rk4's energy error on a small cluster shrinks at order 4", "[nbody][convergence]") {
  ForceModel<double> f;
  f.add(NBody{1.0, 0.2});
  std::vector<double> hs, errors;
  for (double h : {0.04, 0.02, 0.01, 0.005}) {
    ParticleSet<double> b = cluster<double>(8, false, 11);
    const double e0 = energy(b, f).total();
    Stepper<double> s(f, rk4, test::serial_options());
    s.advance(b, h, std::uint64_t(std::llround(2.0 / h)));
    hs.push_back(h);
    errors.push_back(std::abs(energy(b, f).total() - e0));
  }
  const double order = test::fitted_order(hs, errors);
  INFO("errors " << errors[0] << " .. " << errors[3]);
  CHECK(order > 3.7);
  CHECK(order < 4.5);
}

namespace {

template <class T>
std::uint64_t cluster_hash(const Method& method, StepperOptions o, std::size_t bodies) {
  ForceModel<T> f = test::all_local_terms<T>();
  f.add(NBody{0.5, 0.05});
  ParticleSet<T> b = cluster<T>(bodies, true);
  Stepper<T> s(f, method, o);
  s.step(b, T(1e-3));
  REQUIRE(all_finite(b));
  return test::state_hash(b);
}

// Instruction sets on two blocks (the kernel's bits on every set are checked above), thread
// counts and job systems on three, the last one short.
template <class T>
void check_nbody_determinism() {
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t bodies) { return cluster_hash<T>(*m, o, bodies); }, 1100, 2100);
  }
}

}  // namespace

TEST_CASE("nbody: the same bits on every instruction set, thread count and job system", "[coupled][determinism]") {
  check_nbody_determinism<float>();
  check_nbody_determinism<double>();
}

namespace {

// Targets at the origin and a source at distance r along a random direction, mass m. The
// targets are twins (no force on each other) over several lane groups, so that both kinds
// of the fast variant's groups are measured.
constexpr std::size_t kTwinTargets = 40;

// The larger of worst and e, NaN the largest of all: a NaN error must fail the bounds.
double worse(double worst, double e) { return e <= worst ? worst : e; }

double worst_of_one_pull(Isa isa, std::mt19937_64& rng, double eps, bool fast) {
  std::uniform_real_distribution<double> unit(-1, 1), decade(-3, 3);
  const double r = std::pow(10.0, decade(rng)), m = std::pow(10.0, decade(rng));
  double dir[3] = {unit(rng), unit(rng), unit(rng)};
  const double norm = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  ParticleSet<float> b;
  for (std::size_t i = 0; i < kTwinTargets; ++i) b.add({0, 0, 0}, {0, 0, 0}, 1);
  b.add({float(r * dir[0] / norm), float(r * dir[1] / norm), float(r * dir[2] / norm)}, {0, 0, 0}, float(m));
  const float eps2 = float(eps) * float(eps);
  const std::vector<float> sums = kernel_sums(b, isa, 1.0f, eps2, fast);
  const long double dx = b.px()[kTwinTargets], dy = b.py()[kTwinTargets], dz = b.pz()[kTwinTargets];
  const long double mass = 1.0L / b.inv_mass()[kTwinTargets];
  const long double r2 = dx * dx + dy * dy + dz * dz + (long double)eps2;
  const double exact = double(mass * dx / (r2 * std::sqrt(r2)));
  double worst = 0;
  for (std::size_t i = 0; i < kTwinTargets; ++i) worst = worse(worst, std::abs(sums[i] - exact) / std::abs(exact));
  return worst;
}

// The worst relative error of one pull over random distances from 1e-3 to 1e3, masses from
// 1e-3 to 1e3 and softenings from 0 to the distance scale.
double worst_pull_error(Isa isa, bool fast) {
  std::mt19937_64 rng(17);
  double worst = 0;
  for (int k = 0; k < 4000; ++k) {
    worst = worse(worst, worst_of_one_pull(isa, rng, k % 4 == 0 ? 0.0 : std::pow(10.0, k % 7 - 3), fast));
  }
  return worst;
}

}  // namespace

TEST_CASE("nbody fast: each pull within the stated error of the exact one, on every instruction set", "[nbody]") {
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    INFO("isa " << isa_name(isa));
    const double exact = worst_pull_error(isa, false), fast = worst_pull_error(isa, true);
    INFO("exact " << exact << ", fast " << fast);
    CHECK(exact < 5e-7);  // about nine float roundings at most
    // The bounds in forces.hpp: 1e-6 where the start has 14 bits or more, 2e-6 with 12. The
    // start alone, uncorrected, would be off by up to 1.8e-4 and 1.1e-3.
    CHECK(fast < (isa == Isa::sse2 || isa == Isa::avx2 ? 2e-6 : 1e-6));
    CHECK(fast != exact);  // the approximate groups ran
  }
}

TEST_CASE("nbody fast: a cluster's accelerations stay near the exact ones; the same bits on every thread count",
          "[nbody][determinism]") {
  const ParticleSet<float> b = cluster<float>(1500, true);
  const std::vector<float> exact = kernel_sums(b, test::test_isa(), 1.0f, 1e-4f);
  const std::vector<float> fast = kernel_sums(b, test::test_isa(), 1.0f, 1e-4f, true);
  const std::size_t n = b.padded_size();
  double worst = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double a = std::hypot(exact[i], exact[n + i], exact[2 * n + i]);
    for (int k = 0; k < 3; ++k) worst = worse(worst, std::abs(double(fast[k * n + i]) - exact[k * n + i]) / a);
  }
  INFO("worst difference relative to |a| " << worst);
  CHECK(worst > 0);
  CHECK(worst < 1e-4);
  // Calls of five lane groups, so that every other one starts on an odd group, give each
  // body the same kind of group, so the same bits.
  const std::size_t five_groups = 5 * kernels::kernel_table<float>(test::test_isa()).width;
  CHECK(kernel_sums(b, test::test_isa(), 1.0f, 1e-4f, true, five_groups) == fast);
  ForceModel<float> f = test::all_local_terms<float>();
  f.add(NBody{0.5, 0.05, true});
  auto hash = [&](StepperOptions o) {
    ParticleSet<float> run = cluster<float>(2100, true);
    Stepper<float> s(f, rk4, o);
    s.step(run, 1e-3f);
    REQUIRE(all_finite(run));
    return test::state_hash(run);
  };
  const std::uint64_t serial = hash(test::serial_options(best_isa()));
  for (unsigned threads : {2u, 3u}) {
    TbbJobSystem tbb(threads);
    test::ThreadPool pool(threads);
    StepperOptions o;
    o.inline_below = 0;
    o.jobs = &tbb;
    CHECK(hash(o) == serial);
    o.jobs = &pool;
    CHECK(hash(o) == serial);
  }
}

TEST_CASE("nbody fast: a body too far for its squared distance pulls by about nothing, as under the exact sum",
          "[nbody]") {
  // 2e19 apart: the squared distance overflows float (the exact sum's m / inf is 0; the fast
  // estimate's root of inf is 0, and inf 0 was NaN). Bodies 16 .. 31 fill an approximate group
  // on every instruction set.
  ParticleSet<float> b;
  for (int i = 0; i < 32; ++i) b.add({float(i), 0, 0}, {}, 1);
  b.add({2e19f, 0, 0}, {}, 1);
  const std::size_t n = b.padded_size();
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    INFO("isa " << isa_name(isa));
    const std::vector<float> exact = kernel_sums(b, isa, 1.0f, 1e-4f), fast = kernel_sums(b, isa, 1.0f, 1e-4f, true);
    for (std::size_t i = 0; i < b.size(); ++i) {
      INFO("body " << i);
      double pulls = 0;  // each within 2e-6 of its own exact value (forces.hpp)
      for (std::size_t j = 0; j < 32; ++j) {
        if (j != i) pulls += 1 / (std::pow(double(b.px()[j]) - b.px()[i], 2) + 1e-4);
      }
      for (int k = 0; k < 3; ++k) {
        REQUIRE(std::isfinite(fast[k * n + i]));
        CHECK(std::abs(double(fast[k * n + i]) - exact[k * n + i]) <= 2e-6 * pulls);
      }
    }
  }
}

TEST_CASE("nbody: with G = 0 the local terms give the fused path's positions", "[nbody]") {
  for (const Method* m : builtin_methods) {
    INFO("method " << m->name);
    ParticleSet<double> fused = cluster<double>(1100), staged = fused;
    Stepper<double> plain(test::all_local_terms<double>(), *m, test::serial_options());
    ForceModel<double> with_gravity = test::all_local_terms<double>();
    with_gravity.add(NBody{0.0, 0.1});
    Stepper<double> coupled(with_gravity, *m, test::serial_options());
    REQUIRE(plain.fused());
    plain.advance(fused, 0.01, 2);
    coupled.advance(staged, 0.01, 2);
    for (std::size_t i = 0; i < fused.size(); ++i) {
      REQUIRE(fused.position(i) == staged.position(i));
      REQUIRE(fused.velocity(i) == staged.velocity(i));
    }
  }
}

namespace {

// Two heavy bodies a unit apart, a kinematic body 1e-9 from a dynamic one, and a body 1e-20
// from the origin where the padding sits (r^3 underflows there, and massless sources must
// not divide 0 by 0): a step stays finite, exact and fast.
void check_never_nan(double softening, float heavy) {
  ParticleSet<float> b;
  b.add({0, 3, 0}, {0, 0, 0}, heavy);
  b.add({1, 3, 0}, {0, 0, 0}, heavy);
  b.add({1e-20f, 0, 0}, {0, 0, 0}, 1);
  b.add_kinematic({1, 0.5f + 1e-9f, 0});
  b.add({1, 0.5f, 0}, {0, 0, 0}, 1);
  for (const bool fast : {false, true}) {
    ForceModel<float> f;
    f.add(NBody{1, softening, fast});
    for (const Method* m : {&euler, &rk4}) {
      INFO((fast ? "fast " : "exact ") << m->name << ", softening " << softening);
      ParticleSet<float> run = b;
      Stepper<float> s(f, *m, test::serial_options());
      s.step(run, 1e-6f);
      CHECK(all_finite(run));
      CHECK(run.vx()[1] < 0);  // the two heavy bodies pull on each other
      CHECK(run.vx()[0] > 0);
    }
  }
}

}  // namespace

TEST_CASE("nbody: a body's own term and massless neighbours never make NaN", "[nbody]") {
  // A heavy body's own m / eps^3 past float: by its softening (1e-12, mass 1e3: 1e39), and by
  // its mass alone (1e-6, mass 1e30: 1e48), where the softening would let the fast variant
  // leave out the mask.
  check_never_nan(1e-12, 1e3f);
  check_never_nan(1e-6, 1e30f);
}
