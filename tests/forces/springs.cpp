// Spring networks: the two-body frequency, a damped hanging chain at its static stretch,
// Verlet's bounded energy, the explicit methods' stability limits from the chain's
// eigenvalues, exact action and reaction, bit-identical results, and refused networks.
#include <catch2/catch.hpp>

#include <cmath>
#include <complex>
#include <numbers>
#include <random>
#include <set>

#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"
#include "kinema/stability.hpp"
#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

// A vertical chain: body 0 pinned at the origin, bodies 1..n hanging below it `rest` apart,
// each of mass m, joined by springs (k, damping); each free body displaced along y by up
// to `jitter`.
struct Chain {
  ParticleSet<double> bodies;
  ForceModel<double> forces;
};

Chain chain(std::uint32_t n, double rest, double k, double damping, double m, double jitter = 0) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> shake(-jitter, jitter);
  Chain c;
  c.bodies.add_kinematic({0, 0, 0});
  Springs springs;
  for (std::uint32_t i = 1; i <= n; ++i) {
    c.bodies.add({0, -rest * i + shake(rng), 0}, {0, 0, 0}, m);
    springs.pairs.push_back({i - 1, i, rest, k, damping});
  }
  c.forces.add(springs);
  return c;
}

// Eigenvalue number `index` (0 = smallest) of the fixed-free chain's stiffness matrix over
// k: tridiagonal, 2 on the diagonal (1 for the last body), -1 beside it. Bisection on
// Sturm counts.
double chain_eigenvalue(std::uint32_t n, std::uint32_t index) {
  auto below = [&](double x) {  // eigenvalues less than x: negative pivots of A - x I
    std::uint32_t count = 0;
    double pivot = 1;
    for (std::uint32_t i = 0; i < n; ++i) {
      const double diag = (i + 1 == n ? 1.0 : 2.0) - x;
      pivot = diag - (i == 0 ? 0.0 : 1.0 / pivot);
      if (pivot == 0) pivot = -1e-300;
      count += pivot < 0;
    }
    return count;
  };
  double lo = 0, hi = 4;
  while (hi - lo > 1e-15) {
    const double mid = 0.5 * (lo + hi);
    (below(mid) > index ? hi : lo) = mid;
  }
  return 0.5 * (lo + hi);
}

// Largest displacement of a free body from where the chain starts, after `steps` steps.
double displacement_after(Chain c, const Method& method, double h, int steps) {
  const ParticleSet<double> start = c.bodies;
  Stepper<double> s(c.forces, method, test::serial_options());
  s.advance(c.bodies, h, steps);
  double worst = 0;
  for (std::size_t i = 1; i < c.bodies.size(); ++i) {
    const double d = test::distance(c.bodies.position(i), start.position(i));
    worst = std::isfinite(d) ? std::max(worst, d) : INFINITY;
  }
  return worst;
}

}  // namespace

TEST_CASE("springs: two bodies oscillate at sqrt(k (m1 + m2) / (m1 m2))", "[springs]") {
  const double m1 = 1, m2 = 3, k = 12, rest = 1, stretch = 0.1;
  const double omega = std::sqrt(k * (m1 + m2) / (m1 * m2)), period = 2 * std::numbers::pi / omega;
  ParticleSet<double> b;
  b.add({0, 0, 0}, {0, 0, 0}, m1);
  b.add({rest + stretch, 0, 0}, {0, 0, 0}, m2);
  ForceModel<double> f;
  f.add(Springs{{{0, 1, rest, k, 0}}});
  Stepper<double> s(f, rk4, test::serial_options());
  const int steps = 2000;
  s.advance(b, period / steps, steps / 2);
  CHECK(b.px()[1] - b.px()[0] == Approx(rest - stretch).epsilon(1e-10));  // half a period
  s.advance(b, period / steps, steps / 2);
  CHECK(b.px()[1] - b.px()[0] == Approx(rest + stretch).epsilon(1e-10));  // a whole one
  // The centre of mass never moved: m1 x1 + m2 x2 is what it was.
  CHECK(m1 * b.px()[0] + m2 * b.px()[1] == Approx(m2 * (rest + stretch)).epsilon(1e-13));
}

TEST_CASE("springs: a damped hanging chain comes to rest at the static stretch", "[springs]") {
  const std::uint32_t n = 10;
  const double rest = 0.2, k = 50, m = 0.1, g = 9.81;
  Chain c = chain(n, rest, k, 10, m);
  c.forces.add(Gravity{{0, -g, 0}});
  Stepper<double> s(c.forces, rk4, test::serial_options());
  s.advance(c.bodies, 2e-3, 12500);
  // Spring j (from the top) holds the n - j + 1 bodies below it: stretch (n - j + 1) m g / k.
  double y = 0;
  for (std::uint32_t j = 1; j <= n; ++j) {
    y -= rest + (n - j + 1) * m * g / k;
    INFO("body " << j);
    CHECK(c.bodies.py()[j] == Approx(y).margin(1e-9));
    CHECK(std::abs(c.bodies.vy()[j]) < 1e-9);
  }
}

namespace {

// A free square grid with structural and shear springs, no gravity, jittered.
Chain free_grid(std::uint32_t side, double jitter) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> shake(-jitter, jitter);
  Chain c;
  Springs springs;
  auto at = [&](std::uint32_t r, std::uint32_t col) { return r * side + col; };
  for (std::uint32_t r = 0; r < side; ++r) {
    for (std::uint32_t col = 0; col < side; ++col) {
      c.bodies.add({col + shake(rng), r + shake(rng), shake(rng)}, {0, 0, 0}, 1);
      if (col + 1 < side) springs.pairs.push_back({at(r, col), at(r, col + 1), 1, 10, 0});
      if (r + 1 < side) springs.pairs.push_back({at(r, col), at(r + 1, col), 1, 10, 0});
      if (r + 1 < side && col + 1 < side) {
        springs.pairs.push_back({at(r, col), at(r + 1, col + 1), std::sqrt(2.0), 10, 0});
        springs.pairs.push_back({at(r, col + 1), at(r + 1, col), std::sqrt(2.0), 10, 0});
      }
    }
  }
  c.forces.add(springs);
  return c;
}

// The largest |E - E0| / E0 over a run of `steps` steps.
double worst_energy_error(Chain c, const Method& method, double h, int steps) {
  const double e0 = energy(c.bodies, c.forces).total();
  Stepper<double> s(c.forces, method, test::serial_options());
  double worst = 0;
  for (int k = 0; k < steps; ++k) {
    s.step(c.bodies, h);
    worst = std::max(worst, std::abs(energy(c.bodies, c.forces).total() - e0) / e0);
  }
  return worst;
}

}  // namespace

TEST_CASE("springs: velocity_verlet keeps an undamped network's energy bounded", "[springs]") {
  const Chain grid = free_grid(5, 0.1);
  // hw about 0.25 for the stiffest mode; the slowest take about 6 time units a period:
  // 30000 steps are some 100 of its periods.
  const double verlet = worst_energy_error(grid, velocity_verlet, 0.02, 30000);
  CHECK(verlet < 2e-2);
  // Euler on the same network gains energy without bound: the check tells them apart.
  CHECK(worst_energy_error(grid, euler, 0.02, 3000) > 1);
}

TEST_CASE("springs: symplectic Euler on a stiff chain holds below h = 2 / omega_max, not above",
          "[springs][stability]") {
  const std::uint32_t n = 12;
  const double k = 400, m = 0.5;
  const double omega_max = std::sqrt(k / m * chain_eigenvalue(n, n - 1));
  const double limit = 2 / omega_max;
  const Chain c = chain(n, 1, k, 0, m, 0.01);
  CHECK(displacement_after(c, symplectic_euler, 0.97 * limit, 4000) < 0.5);
  CHECK(displacement_after(c, symplectic_euler, 1.03 * limit, 4000) > 1e3);
  // Known before a single step: the stiffness estimate finds omega_max, and the limit.
  const StiffnessEstimate e = estimate_stiffness(c.bodies, c.forces);
  CHECK(e.magnitude == Approx(omega_max).epsilon(0.01));
  CHECK(largest_stable_step(symplectic_euler, e) == Approx(limit).epsilon(0.02));
}

TEST_CASE("springs: explicit Euler on a damped stiff chain diverges past the limit of its "
          "eigenvalues, not below", "[springs][stability]") {
  // Each mode of stiffness eigenvalue mu has roots of l^2 + (c/m) mu l + (k/m) mu = 0; Euler
  // is stable while |1 + h l| <= 1 for all of them. The stiffest mode is overdamped here:
  // its fast root binds.
  const std::uint32_t n = 8;
  const double k = 100, c = 40, m = 1;
  double limit = INFINITY;
  for (std::uint32_t j = 0; j < n; ++j) {
    const double mu = chain_eigenvalue(n, j), b = c / m * mu, q = k / m * mu;
    for (double sign : {-1.0, 1.0}) {
      const std::complex<double> root = (-b + sign * std::sqrt(std::complex<double>(b * b - 4 * q))) / 2.0;
      limit = std::min(limit, -2 * root.real() / std::norm(root));  // |1 + h l| = 1
    }
  }
  const Chain chained = chain(n, 1, k, c, m, 0.01);
  CHECK(displacement_after(chained, euler, 0.97 * limit, 3000) < 0.05);
  CHECK(displacement_after(chained, euler, 1.03 * limit, 3000) > 1e3);
  CHECK(largest_stable_step(euler, estimate_stiffness(chained.bodies, chained.forces)) == Approx(limit).epsilon(0.02));
  // Undamped, Euler has no stable step at all: its factor exceeds 1 on the imaginary axis.
  const Chain undamped = chain(n, 1, k, 0, m, 0.01);
  CHECK(displacement_after(undamped, euler, 0.1 * limit, 20000) > 0.05);
}

TEST_CASE("springs: action equals reaction to the bit, and momentum is conserved", "[springs]") {
  const Chain grid = free_grid(9, 0.2);
  ParticleSet<double> b = grid.bodies;
  for (std::size_t i = 0; i < b.size(); i += 3) b.set_velocity(i, {0.3, -0.1, 0.2});
  const Vec3<double> p0 = momentum(b);
  Stepper<double> s(grid.forces, rk4, test::serial_options());
  s.advance(b, 0.01, 100);
  CHECK(test::distance(momentum(b), p0) < 1e-12);
  // One spring between two bodies: the forces are exact opposites.
  ParticleSet<float> two;
  two.add({0.1f, 0.7f, -0.3f}, {0, 0, 0.5f}, 1);  // damping sees a relative velocity
  two.add({1.3f, -0.2f, 0.9f}, {0, 0, 0}, 1);
  ForceModel<float> f;
  f.add(Springs{{{0, 1, 0.5, 3.7, 0.9}}});
  Stepper<float> e(f, euler, test::serial_options());
  e.step(two, 0.125f);
  CHECK(two.vx()[0] == -two.vx()[1]);
  CHECK(two.vy()[0] == -two.vy()[1]);
  CHECK(two.vx()[0] != 0);
}

namespace {

template <class T>
std::uint64_t cloth_hash(const Method& method, StepperOptions o, std::uint32_t side) {
  const Chain grid = free_grid(side, 0.2);
  ParticleSet<T> b;
  for (std::size_t i = 0; i < grid.bodies.size(); ++i) {
    const auto x = grid.bodies.position(i);
    b.add({T(x[0]), T(x[1]), T(x[2])}, {T(0.01 * (i % 5)), 0, 0}, T(1 + 0.1 * (i % 3)));
  }
  ForceModel<T> f = test::all_local_terms<T>();
  f.add(Springs{{grid.forces.springs().begin(), grid.forces.springs().end()}});
  Stepper<T> s(f, method, o);
  s.advance(b, T(0.01), 3);
  REQUIRE(all_finite(b));
  return test::state_hash(b);
}

template <class T>
void check_spring_determinism() {
  for (const Method* m : {&euler, &rk4, &velocity_verlet}) {
    INFO(m->name);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t side) { return cloth_hash<T>(*m, o, std::uint32_t(side)); }, 40, 40);
  }
}

}  // namespace

TEST_CASE("springs: the same bits on every instruction set, thread count and job system", "[coupled][determinism]") {
  check_spring_determinism<float>();
  check_spring_determinism<double>();
}

TEST_CASE("springs: bad networks are refused, naming the pair", "[springs][errors]") {
  auto refused = [](std::vector<SpringPair> pairs) {
    try {
      ForceModel<float>().add(Springs{std::move(pairs)});
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  CHECK(refused({{0, 1, 1, 1, 0}, {2, 2, 1, 1, 0}}) == "springs.pairs[1]: joins body 2 to itself");
  CHECK(refused({{0, 1, 1, 1, 0}, {3, 4, 1, 1, 0}, {1, 0, 2, 1, 0}}) ==
        "springs.pairs[2]: repeats springs.pairs[0] (bodies 0 and 1)");
  CHECK(refused({{0, 1, -1, 1, 0}}) == "springs.pairs[0].rest: must be finite and >= 0");
  CHECK(refused({{0, 1, 1, NAN, 0}}) == "springs.pairs[0].k: must be finite and >= 0");
  CHECK(refused({{0, 1u << 30, 1, 1, 0}}) ==
        "springs.pairs[0].j: body 1073741824 is past the largest index 1073741823");
  // A network that reaches past the set is refused at the step, before anything moves.
  ForceModel<double> f;
  f.add(Springs{{{0, 5, 1, 1, 0}}});
  ParticleSet<double> b;
  b.add({0, 0, 0}, {1, 0, 0}, 1);
  Stepper<double> s(f, rk4, test::serial_options());
  CHECK_THROWS_WITH(s.step(b, 0.1), "springs: a pair joins body 5, but the set has 1 bodies");
  CHECK(b.px()[0] == 0);
  // The energy of that set is refused alike (it left the spring out, a potential too small).
  CHECK_THROWS_WITH(energy(b, f), "springs: a pair joins body 5, but the set has 1 bodies");
  // The largest index on a 3-body set: refused before the network is laid out (its layout
  // grows with the largest index: gigabytes here), so the stepper holds a few bytes.
  ForceModel<float> far;
  far.add(Springs{{{0, (1u << 30) - 1, 1, 1, 0}}});
  ParticleSet<float> three;
  for (float x : {0.f, 1.f, 2.f}) three.add({x, 0, 0}, {0, 0, 0}, 1);
  Stepper<float> reaching(far, rk4, test::serial_options());
  CHECK_THROWS_WITH(reaching.step(three, 0.1f), "springs: a pair joins body 1073741823, but the set has 3 bodies");
  CHECK(reaching.scratch_bytes() < (std::size_t(1) << 20));
  CHECK(three.px()[2] == 2);
}

namespace {

// 2500 bodies (not a multiple of 16) joined at random, 1 to 12 springs each: the slices
// reach many offsets, so the kernels take the layout in model order and gather.
template <class T>
struct RandomNetwork {
  ParticleSet<T> bodies;
  ForceModel<T> forces;
};

template <class T>
RandomNetwork<T> random_network() {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> pos(-3, 3), vel(-1, 1), param(0.2, 2);
  RandomNetwork<T> net;
  const std::uint32_t n = 2500;
  for (std::uint32_t i = 0; i < n; ++i) {
    net.bodies.add({T(pos(rng)), T(pos(rng)), T(pos(rng))}, {T(vel(rng)), T(vel(rng)), T(vel(rng))}, T(param(rng)));
  }
  Springs springs;
  std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
  for (std::uint32_t i = 0; i < n; ++i) {
    for (std::uint32_t k = 0; k < 1 + i % 6; ++k) {
      const std::uint32_t j = std::uint32_t(rng() % n);
      if (j == i || !seen.insert({std::min(i, j), std::max(i, j)}).second) continue;
      springs.pairs.push_back({i, j, param(rng), 10 * param(rng), param(rng)});
    }
  }
  net.forces.add(springs);
  return net;
}

// The spring kernel's forces on every body, on one instruction set.
template <class T>
std::vector<T> kernel_forces(const RandomNetwork<T>& net, Isa isa) {
  CoupledForces<T> lowered = lower_coupled<T>(net.forces);
  lowered.springs.lay_out();
  const std::size_t n = net.bodies.padded_size();
  AlignedArray<T> force(3 * n);
  const T* x[3] = {net.bodies.px(), net.bodies.py(), net.bodies.pz()};
  const T* v[3] = {net.bodies.vx(), net.bodies.vy(), net.bodies.vz()};
  T* f[3] = {force.data(), force.data() + n, force.data() + 2 * n};
  const auto& table = kernels::kernel_table<T>(isa);
  for (std::size_t begin = 0; begin < n; begin += kBlockBodies) {
    table.springs(lowered.springs.job(x, v, f), begin, std::min(n, begin + kBlockBodies));
  }
  return {force.data(), force.data() + 3 * n};
}

template <class T>
void check_random_network(double tolerance) {
  const RandomNetwork<T> net = random_network<T>();
  const std::vector<T> scalar = kernel_forces(net, Isa::scalar);
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    INFO("isa " << isa_name(isa));
    if (isa_available(isa)) CHECK(kernel_forces(net, isa) == scalar);
  }
  // Against the formula in long double, relative to the sum of the springs' magnitudes.
  const std::size_t n = net.bodies.padded_size();
  std::vector<long double> want(3 * n, 0), scale(n, 0);
  const auto& b = net.bodies;
  for (const SpringPair& p : net.forces.springs()) {
    long double d[3], dv[3], len2 = 0;
    const T* x[3] = {b.px(), b.py(), b.pz()};
    const T* v[3] = {b.vx(), b.vy(), b.vz()};
    for (int c = 0; c < 3; ++c) {
      d[c] = (long double)x[c][p.i] - x[c][p.j], dv[c] = (long double)v[c][p.i] - v[c][p.j], len2 += d[c] * d[c];
    }
    const long double len = std::sqrt(len2), along = (dv[0] * d[0] + dv[1] * d[1] + dv[2] * d[2]) / len;
    const long double coefficient = -T(p.k) * (len - T(p.rest)) - T(p.damping) * along;
    for (int c = 0; c < 3; ++c) {
      want[c * n + p.i] += coefficient * d[c] / len, want[c * n + p.j] -= coefficient * d[c] / len;
    }
    scale[p.i] += std::abs(coefficient), scale[p.j] += std::abs(coefficient);
  }
  double worst = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    for (int c = 0; c < 3; ++c) worst = std::max(worst, double(std::abs(scalar[c * n + i] - want[c * n + i]) / scale[i]));
  }
  CHECK(worst < tolerance);
}

}  // namespace

TEST_CASE("springs: an irregular network gives the same bits on every instruction set, and the "
          "formula's forces", "[coupled]") {
  check_random_network<float>(1e-5);
  check_random_network<double>(1e-13);
}

TEST_CASE("springs: the irregular network steps to the same bits on any thread count", "[coupled][determinism]") {
  const RandomNetwork<double> net = random_network<double>();
  auto hash = [&](StepperOptions o) {
    ParticleSet<double> b = net.bodies;
    Stepper<double> s(net.forces, rk4, o);
    s.advance(b, 1e-3, 3);
    return test::state_hash(b);
  };
  const std::uint64_t serial = hash(test::serial_options());
  for (unsigned threads : {2u, 3u}) {
    TbbJobSystem tbb(threads);
    StepperOptions o;
    o.jobs = &tbb;
    o.workers = WorkerChoice::all;
    CHECK(hash(o) == serial);
  }
}

TEST_CASE("springs: the frequency bound holds the chain's fastest mode, and is close", "[springs]") {
  const std::uint32_t n = 50;
  const double k = 300, m = 0.2;
  const Chain c = chain(n, 1, k, 0, m);
  const double bound = spring_frequency_bound(c.bodies, c.forces.springs());
  const double omega_max = std::sqrt(k / m * chain_eigenvalue(n, n - 1));
  CHECK(bound >= omega_max);
  CHECK(bound < 1.001 * omega_max);  // interior bodies: 2 sqrt(k / m), the chain's limit
  CHECK(spring_frequency_bound(c.bodies, std::span<const SpringPair>{}) == 0);
}
