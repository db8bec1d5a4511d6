// Rigid bodies under coupled terms and point springs: body springs, a top held at its tip,
// N-body gravity among their centres, on every method.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <boost/math/special_functions/ellint_1.hpp>

#include "support.hpp"

using namespace kinema;

namespace {

#ifdef KINEMA_SANITIZED
constexpr std::size_t kSeveralBlocks = kBlockBodies + 76;
#else
constexpr std::size_t kSeveralBlocks = 2 * kBlockBodies + 52;
#endif

const std::array<const Method*, 9> every_method = {&euler, &midpoint, &heun, &rk4, &symplectic_euler,
                                                   &velocity_verlet, &bs3, &dopri5, &rk6};

// Two tumbling bodies of different mass and inertia, moving apart.
RigidBodySet<double> tumbling_pair() {
  RigidBodySet<double> b;
  b.add({{-1, 0, 0}, {0, 0.5, 0}, {0.9, 0.1, -0.3, 0.2}, {0.3, -0.2, 0.5}, 1, {0.2, 0.3, 0.4}});
  b.add({{1, 0.2, 0}, {0, -0.25, 0.1}, {0.7, -0.2, 0.4, 0.1}, {-0.1, 0.4, 0.2}, 2, {0.5, 0.3, 0.2}});
  return b;
}

// A spring between points off both centres: it pulls and turns both bodies.
ForceModel<double> joined_pair(double damping) {
  ForceModel<double> f;
  f.add(BodySprings{{{0, 1, {0.3, 0.2, 0}, {-0.2, 0.1, 0.3}, 1.5, 20, damping}}});
  return f;
}

double largest_change(const Vec3<double>& a, const Vec3<double>& b) {
  return std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
}

struct Drift {
  double energy = 0, angular_momentum = 0, momentum = 0;  // the largest changes over a run
};

Drift drift_of(const Method& method, const ForceModel<double>& f, double h, double t_end) {
  RigidBodySet<double> b = tumbling_pair();
  Stepper<double> s(f, method, test::serial_options());
  const double e0 = energy(b, f).total();
  const Vec3<double> l0 = angular_momentum(b), p0 = momentum(b.centers());
  Drift d;
  for (long k = 0; k < std::lround(t_end / h); ++k) {
    s.step(b, h);
    d.energy = std::max(d.energy, std::abs(energy(b, f).total() - e0));
    d.angular_momentum = std::max(d.angular_momentum, largest_change(angular_momentum(b), l0));
    d.momentum = std::max(d.momentum, largest_change(momentum(b.centers()), p0));
  }
  return d;
}

// The world direction of body 0's z axis.
Vec3<double> body_axis(const RigidBodySet<double>& b) {
  const Quat<double> q = b.orientation(0);
  return {2 * (q[1] * q[3] + q[0] * q[2]), 2 * (q[2] * q[3] - q[0] * q[1]), 1 - 2 * (q[1] * q[1] + q[2] * q[2])};
}

// A symmetric top (mass 1, centre 0.5 from its tip, moments 0.05, 0.05, 0.1) spinning at 100
// rad/s about its axis, tilted 30 degrees from the vertical (y), its tip held at the origin
// by a stiff point spring. With `precession` > 0 it starts precessing at that rate, as a top
// on a fixed pivot does steadily (no nutation).
struct Top {
  double mass = 1, arm = 0.5, i1 = 0.05, i3 = 0.1, spin = 100, tilt = std::numbers::pi / 6, g = 9.81;

  RigidBodySet<double> bodies(double precession) const {
    const double c = std::cos(tilt), s = std::sin(tilt);
    const Vec3<double> axis{s, c, 0};
    const double half = std::numbers::pi / 4;  // body z onto the axis: a quarter turn about z x axis
    const Quat<double> q{std::cos(half), -std::sin(half) * c, std::sin(half) * s, 0};
    Vec3<double> l;  // omega = precession y + (spin - precession cos) axis, L = I omega
    for (int d = 0; d < 3; ++d) {
      const double omega = (d == 1 ? precession : 0) + (spin - precession * c) * axis[d];
      l[d] = i3 * spin * axis[d] + i1 * (omega - spin * axis[d]);
    }
    RigidBodySet<double> b;
    b.add({{arm * s, arm * c, 0}, {0, 0, -precession * arm * s}, q, l, mass, {i1, i1, i3}});
    return b;
  }
  ForceModel<double> forces(double k, double damping) const {
    ForceModel<double> f;
    f.add(Gravity{{0, -g, 0}}).add(PointSpring{{0, 0, -arm}, {0, 0, 0}, k, damping});
    return f;
  }
  double pivot_inertia() const { return i1 + mass * arm * arm; }
  // The gyroscopic formula m g l / (I3 omega3), and the steady rate of a top on a fixed pivot:
  // the slow root of I1' cos(tilt) W^2 - I3 omega3 W + m g l = 0.
  double gyroscopic() const { return mass * g * arm / (i3 * spin); }
  double steady() const {
    const double a = pivot_inertia() * std::cos(tilt), b = i3 * spin, c = mass * g * arm;
    return (b - std::sqrt(b * b - 4 * a * c)) / (2 * a);
  }
};

}  // namespace

TEST_CASE("a body spring conserves momentum to round-off on every method", "[rigid][springs]") {
  for (const Method* m : every_method) {
    INFO(m->name);
    const Drift d = drift_of(*m, joined_pair(0.5), 0.01, 2);
    CHECK(d.momentum < 2e-15);
  }
}

TEST_CASE("a body spring's energy and angular momentum errors converge at each method's order",
          "[rigid][springs][convergence]") {
  for (const Method* m : every_method) {
    INFO(m->name);
    const double h0 = m->order >= 5 ? 0.04 : 0.02;
    std::vector<double> steps, energy, angular;
    for (double h : {h0, h0 / 2, h0 / 4}) {
      const Drift d = drift_of(*m, joined_pair(0), h, 2);
      steps.push_back(h), energy.push_back(d.energy), angular.push_back(d.angular_momentum);
    }
    CHECK(test::fitted_order(steps, energy) > m->order - 0.5);
    // Kicks and drifts conserve angular momentum exactly: each kick's torques and forces
    // about the origin cancel pairwise, and a drift moves x along v.
    if (m->kind == MethodKind::kick_drift) {
      CHECK(angular.back() < 1e-13);
    } else {
      CHECK(test::fitted_order(steps, angular) > m->order - 0.5);
    }
  }
}

TEST_CASE("a spring's force on one body is the exact negation of its force on the other", "[rigid][springs]") {
  // Unit masses at rest: one Euler step of a power of two gives v = h F exactly.
  RigidBodySet<double> b;
  b.add({{-1, 0, 0}, {}, {0.9, 0.1, -0.3, 0.2}, {0.3, -0.2, 0.5}, 1, {0.2, 0.3, 0.4}});
  b.add({{1, 0.2, 0}, {}, {0.7, -0.2, 0.4, 0.1}, {-0.1, 0.4, 0.2}, 1, {0.5, 0.3, 0.2}});
  Stepper<double> s(joined_pair(0.5), euler, test::serial_options());
  s.step(b, 0.125);
  const Vec3<double> v0 = b.centers().velocity(0), v1 = b.centers().velocity(1);
  for (int d = 0; d < 3; ++d) {
    CHECK(v0[d] != 0);
    CHECK(v0[d] == -v1[d]);
  }
}

TEST_CASE("a heavy top on a point spring precesses at the steady rate, off the gyroscopic formula by its own error",
          "[rigid][springs][analytic]") {
  const Top top;
  const double steady = top.steady(), gyroscopic = top.gyroscopic();
  RigidBodySet<double> b = top.bodies(steady);
  Stepper<double> s(top.forces(1e6, 200), rk4, test::serial_options());
  const double t = 2, h = 2e-4;
  s.advance(b, h, std::uint64_t(std::lround(t / h)));
  const Vec3<double> axis = body_axis(b);
  const double measured = std::atan2(-axis[2], axis[0]) / t;
  // The pivot gives by F / k = 1e-5 of the arm: the rate is the fixed pivot's to ~1e-5.
  CHECK(std::abs(measured - steady) < 5e-5 * steady);
  // The formula drops I1' W^2 cos(tilt) against I3 omega3 W: relative error ~ I1' cos(tilt) W / (I3 omega3),
  // 1.27% here; the measured rate is off the formula by that much.
  const double formula_error = top.pivot_inertia() * std::cos(top.tilt) * gyroscopic / (top.i3 * top.spin);
  CHECK(std::abs(measured / gyroscopic - 1) == Approx(formula_error).epsilon(0.05));
  CHECK(std::acos(axis[1]) == Approx(top.tilt).epsilon(1e-4));  // no nutation to speak of
}

TEST_CASE("rk4 keeps a top's vertical angular momentum and spin to its order", "[rigid][springs][convergence]") {
  const Top top;
  const ForceModel<double> f = top.forces(1e4, 0);  // undamped: both are invariants
  std::vector<double> steps, vertical, spin;
  for (double h : {4e-3, 2e-3, 1e-3, 5e-4}) {
    RigidBodySet<double> b = top.bodies(0);
    Stepper<double> s(f, rk4, test::serial_options());
    const auto spin_now = [&] {
      const Vec3<double> a = body_axis(b), l = {b.l(0)[0], b.l(1)[0], b.l(2)[0]};
      return l[0] * a[0] + l[1] * a[1] + l[2] * a[2];
    };
    const double vertical0 = angular_momentum(b)[1], spin0 = spin_now();
    double dv = 0, ds = 0;
    for (long k = 0; k < std::lround(1 / h); ++k) {
      s.step(b, h);
      dv = std::max(dv, std::abs(angular_momentum(b)[1] - vertical0));
      ds = std::max(ds, std::abs(spin_now() - spin0));
    }
    steps.push_back(h), vertical.push_back(dv), spin.push_back(ds);
  }
  CHECK(test::fitted_order(steps, vertical) > 3.7);
  CHECK(test::fitted_order(steps, spin) > 3.7);
}

TEST_CASE("N-body gravity pulls rigid bodies' centres as it pulls particles", "[rigid][nbody]") {
  RigidBodySet<double> rigid;
  ParticleSet<double> particles;
  for (int i = 0; i < 5; ++i) {
    const Vec3<double> x{std::cos(i * 1.3) * 2, std::sin(i * 0.7), 0.3 * i}, v{0.1 * i, -0.2, 0.05 * i};
    rigid.add({x, v, {1, 0.1 * i, 0, 0.2}, {0.1, 0.2 * i, 0.3}, 1.0 + i, {1, 2, 3}});
    particles.add(x, v, 1.0 + i);
  }
  ForceModel<double> f;
  f.add(NBody{0.2, 0.5});  // gentle: no close pass to amplify the paths' different rounding
  const RigidBodySet<double> start = rigid;
  Stepper<double> on_rigid(f, rk4, test::serial_options()), on_particles(f, rk4, test::serial_options());
  on_rigid.advance(rigid, 0.01, 100);
  on_particles.advance(particles, 0.01, 100);
  for (std::size_t i = 0; i < 5; ++i) {
    CHECK(test::distance(rigid.centers().position(i), particles.position(i)) < 1e-12);
    CHECK(rigid.angular_momentum(i) == start.angular_momentum(i));  // no torque on a point mass
  }
}

TEST_CASE("rigid coupled terms: the same bits on every ISA, thread count and job system", "[rigid][springs][determinism]") {
  const auto hash = [](StepperOptions o, std::size_t n) {
    RigidBodySet<double> b;
    BodySprings springs;
    for (std::size_t i = 0; i < n; ++i) {
      const double a = double(i % 13) / 13;
      b.add({{double(i % 40), a, double(i / 40)}, {a, 0, -a}, {1, a, 0.2, -0.1}, {a, 0.5, 0.1}, 1 + a, {1, 1.5, 2}});
      if (i > 0) springs.springs.push_back({std::uint32_t(i - 1), std::uint32_t(i), {0.2, 0, 0.1}, {-0.1, 0.3, 0}, 1, 5, 0.1});
    }
    ForceModel<double> f;
    f.add(Gravity{}).add(PointSpring{{0, 0.5, 0}, {0, 10, 0}, 0.5, 0.05}).add(std::move(springs)).add(NBody{0.01, 0.5});
    f.add([](const RigidBlock<double>& v) {
      for (std::size_t i = 0; i < v.count; ++i) v.tx[i] -= 0.1 * v.wx[i];
    });
    Stepper<double> s(f, rk4, o);
    s.advance(b, 0.01, 5);
    Stepper<double> kd(f, velocity_verlet, o);
    kd.advance(b, 0.01, 5);
    return test::state_hash(b);
  };
  // Three blocks, the last short; two under the sanitizers (N-body's n^2 is most of the time).
  test::check_same_bits_everywhere(hash, 64, kSeveralBlocks);
}

TEST_CASE("a throw among coupled rigid terms leaves the set as before the step that threw", "[rigid][springs][embedding]") {
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    // Steps 0 and 1 of the call complete; step 2 (from t = 0.02) throws inside.
    ForceModel<double> throwing = joined_pair(0.1);
    throwing.add([](const RigidBlock<double>& v) {
      if (v.t > 0.021) throw std::runtime_error("from the game");
    });
    RigidBodySet<double> b = tumbling_pair(), expected = tumbling_pair();
    Stepper<double> s(throwing, *m, test::serial_options());
    CHECK_THROWS_AS(s.advance(b, 0.01, 5), std::runtime_error);
    Stepper<double> reference(joined_pair(0.1), *m, test::serial_options());
    reference.advance(expected, 0.01, 2);
    CHECK(test::state_hash(b) == test::state_hash(expected));
    CHECK(s.time() == reference.time());
  }
}

TEST_CASE("body springs are checked: indices, parameters, points, the set's size", "[rigid][springs][forces]") {
  ForceModel<double> f;
  CHECK_THROWS_WITH(f.add(BodySprings{{{1, 1, {}, {}, 0, 1, 0}}}), Catch::Contains("body_springs[0]: joins body 1 to itself"));
  CHECK_THROWS_WITH(f.add(BodySprings{{{0, 1, {}, {}, 0, -1, 0}}}), Catch::Contains("body_springs[0].k"));
  CHECK_THROWS_WITH(f.add(BodySprings{{{0, 1, {NAN, 0, 0}, {}, 0, 1, 0}}}), Catch::Contains("body_springs[0].point_i"));
  ForceModel<float> big;
  big.add(BodySprings{{{0, 1, {1e300, 0, 0}, {}, 0, 1, 0}}});
  CHECK_THROWS_WITH(Stepper<float>(big, rk4), Catch::Contains("body_springs[0].point_i") && Catch::Contains("overflows float"));
  f.add(BodySprings{{{0, 2, {}, {}, 0, 1, 0}, {0, 2, {1, 0, 0}, {}, 0, 1, 0}}});  // two springs, one pair: allowed
  RigidBodySet<double> b = tumbling_pair();
  const RigidBodySet<double> before = b;
  Stepper<double> s(f, rk4, test::serial_options());
  CHECK_THROWS_WITH(s.step(b, 0.01), Catch::Contains("joins body 2, but the set has 2 bodies"));
  CHECK(test::state_hash(b) == test::state_hash(before));
}

TEST_CASE("particles ignore body springs and point springs", "[rigid][springs]") {
  ForceModel<double> with = joined_pair(0);
  with.add(PointSpring{{1, 0, 0}, {5, 5, 5}, 3, 0}).add(Gravity{});
  ForceModel<double> without;
  without.add(Gravity{});
  const auto run = [](const ForceModel<double>& f) {
    ParticleSet<double> p = test::cloud<double>(10);
    Stepper<double> s(f, rk4, test::serial_options());
    s.advance(p, 0.01, 10);
    return test::state_hash(p);
  };
  CHECK(run(with) == run(without));
}

namespace {

// A torque-free body with moments 1, 2, 3, starting with body-frame omega (1, 0, 0.6): near
// the separatrix, it spins mostly about its intermediate axis and flips over and back. From
// Euler's equations (Landau and Lifshitz, section 37): omega_2 = A2 sn(rate t, m), zero at
// t = n 2 K(m) / rate, the flips.
struct Flipping {
  double inertia[3] = {1, 2, 3}, w1 = 1, w3 = 0.6;

  double l2() const { return inertia[0] * inertia[0] * w1 * w1 + inertia[2] * inertia[2] * w3 * w3; }
  double e2() const { return inertia[0] * w1 * w1 + inertia[2] * w3 * w3; }  // twice the energy
  double amplitude() const { return std::sqrt((e2() * inertia[2] - l2()) / (inertia[1] * (inertia[2] - inertia[1]))); }
  double rate() const {
    return std::sqrt((inertia[2] - inertia[1]) * (l2() - e2() * inertia[0]) / (inertia[0] * inertia[1] * inertia[2]));
  }
  double flip_time() const {
    const double m = (inertia[1] - inertia[0]) * (e2() * inertia[2] - l2()) / ((inertia[2] - inertia[1]) * (l2() - e2() * inertia[0]));
    return 2 * boost::math::ellint_1(std::sqrt(m)) / rate();
  }
  RigidBodySet<double> bodies() const {
    RigidBodySet<double> b;
    b.add({{}, {}, {1, 0, 0, 0}, {inertia[0] * w1, 0, inertia[2] * w3}, 1, {inertia[0], inertia[1], inertia[2]}});
    return b;
  }
};

// The body-frame omega_2 of body 0: omega . (R e_y).
double body_omega_y(const RigidBodySet<double>& b) {
  const Quat<double> q = b.orientation(0);
  const Vec3<double> w = b.angular_velocity(0);
  const double ey[3] = {2 * (q[1] * q[2] - q[0] * q[3]), 1 - 2 * (q[1] * q[1] + q[3] * q[3]), 2 * (q[2] * q[3] + q[0] * q[1])};
  return w[0] * ey[0] + w[1] * ey[1] + w[2] * ey[2];
}

// How far off the first flip comes: omega_2 at the analytic flip time over its rate there.
double first_flip_error(double tolerance) {
  const Flipping body;
  RigidBodySet<double> b = body.bodies();
  Stepper<double> s(ForceModel<double>{}, dopri5, test::serial_options());
  Tolerances t;
  t.rtol = t.atol = tolerance;
  const AdaptiveStats stats = s.advance_to(b, body.flip_time(), t);
  CHECK(stats.accepted > 10);
  CHECK(s.time() == body.flip_time());
  return std::abs(body_omega_y(b)) / (body.amplitude() * body.rate());
}

}  // namespace

TEST_CASE("dopri5 with error control flips a torque-free body at the analytic time", "[rigid][adaptive][analytic]") {
  const double flip = Flipping{}.flip_time();  // 9.067 s
  const double coarse = first_flip_error(1e-8), fine = first_flip_error(1e-10);
  // The global error of a run of ~60 steps at a local tolerance tol: measured 23 tol and 18 tol.
  CHECK(coarse < 50 * 1e-8 * flip);
  CHECK(fine < 50 * 1e-10 * flip);
  CHECK(coarse / fine > 30);
}

TEST_CASE("rigid error control refuses tolerances under the round-off of a turning body at rest", "[rigid][adaptive][errors]") {
  // Its centre at the origin, at rest: the centres' |x| + |v| is 0, but the norm holds q (up
  // to 1) and L. rtol 1e-18 once crawled on at 1e-17 s a step, with no stop to end the call.
  RigidBodySet<double> b;
  b.add({.angular_momentum = {0, 0, 2}, .inertia = {1, 2, 3}});
  Stepper<double> s(ForceModel<double>{}, dopri5, test::serial_options());
  CHECK_THROWS_WITH(s.advance_to(b, 1e-3, {1e-18, 0}),
                    Catch::Contains("a sixteenth of an ulp of their largest |q| + |L|): no step can meet them"));
  CHECK(s.time() == 0);
  CHECK(s.advance_to(b, 1e-3, {1e-12, 0}).accepted > 0);
}

TEST_CASE("rigid error control to a far end starts from the estimate and stops at the floor", "[rigid][adaptive][events]") {
  // "Until the event": its first step once was 0.01 (t_end - t), accepted whole for a body in
  // free fall (its error estimate 0), the crossing placed within a 1e28 s step.
  const auto landing = []<class T>(T, double t_end) {
    ForceModel<T> f;
    f.add(Gravity{});
    RigidBodySet<T> b;
    b.add({.position = {0, 10, 0}});
    Stepper<T> s(f, dopri5, test::serial_options());
    EventOptions<T> floor;
    floor.events.push_back({PlaneEvent{{0, 1, 0}, 0}, Crossing::down, EventAction::stop});
    s.set_events(floor);
    s.advance_to(b, t_end, {1e-6, 1e-6});
    REQUIRE(s.stopped_at_event());
    return s.event_hits().at(0).time;
  };
  const double exact = std::sqrt(20 / 9.81);
  for (const double t_end : {1e3, 1e30, std::numeric_limits<double>::max()}) {
    CHECK(landing(0.0, t_end) == Approx(exact).epsilon(1e-9));
  }
  CHECK(landing(0.0f, 1e30) == Approx(exact).epsilon(1e-5));  // a float clock: inf, then 1e38, were refused
}

TEST_CASE("error control on coupled rigid bodies reaches a fine fixed-step solution", "[rigid][adaptive][springs]") {
  const ForceModel<double> f = joined_pair(0.3);
  RigidBodySet<double> adaptive = tumbling_pair(), fine = tumbling_pair();
  Stepper<double> s(f, dopri5, test::serial_options());
  Tolerances t;
  t.rtol = t.atol = 1e-9;
  const AdaptiveStats stats = s.advance_to(adaptive, 2, t);
  Stepper<double> reference(f, rk6, test::serial_options());
  reference.advance(fine, 1e-3, 2000);
  for (std::size_t i = 0; i < 2; ++i) {
    CHECK(test::distance(adaptive.centers().position(i), fine.centers().position(i)) < 1e-7);
    const Quat<double> a = adaptive.orientation(i), r = fine.orientation(i);
    for (int k = 0; k < 4; ++k) CHECK(std::abs(a[k] - r[k]) < 1e-7);
  }
  CHECK(stats.rejected < stats.accepted);
  Tolerances capped = t;
  capped.limit_to_stable_step = true;
  CHECK_THROWS_WITH(s.advance_to(adaptive, 3, capped), Catch::Contains("particles only"));
}

TEST_CASE("rigid error control: the same steps and bits on every thread count", "[rigid][adaptive][determinism]") {
  const auto hash = [](StepperOptions o, std::size_t n) {
    RigidBodySet<double> b;
    for (std::size_t i = 0; i < n; ++i) {
      const double a = double(i % 11) / 11;
      b.add({{a, 0, double(i)}, {0, a, 0}, {1, a, -a, 0.3}, {a, 1 - a, 0.5}, 1 + a, {1, 2 + a, 3}});
    }
    ForceModel<double> f;
    f.add(Gravity{}).add(PointSpring{{0.1, 0.2, 0}, {0, 0, 0}, 2, 0.1});
    Stepper<double> s(f, dopri5, o);
    Tolerances t;
    t.rtol = t.atol = 1e-7;
    const AdaptiveStats stats = s.advance_to(b, 0.5, t);
    return test::state_hash(b) ^ stats.accepted ^ (stats.rejected << 20);
  };
  test::check_same_bits_everywhere(hash, 40, kSeveralBlocks);
}

namespace {

// Four boxes (half extents 0.3, 0.5, 0.2) hanging in a chain from a kinematic anchor, each
// joint two corner springs (rest 0.1), under gravity: their rest state, found by relaxing them
// with drag, then at rest.
struct BoxChain {
  static constexpr int boxes = 4;
  static constexpr double hx = 0.3, hy = 0.5, hz = 0.2, gap = 0.1;

  static ForceModel<double> forces(double k) {
    ForceModel<double> f;
    f.add(Gravity{});
    BodySprings s;
    for (int i = 1; i <= boxes; ++i) {
      for (double side : {-1.0, 1.0}) {
        const Vec3<double> above{side * hx, i == 1 ? 0 : -hy, 0};
        s.springs.push_back({std::uint32_t(i - 1), std::uint32_t(i), above, {side * hx, hy, 0}, gap, k, 0});
      }
    }
    return f.add(s);
  }
  static RigidBodySet<double> at_rest(double k) {
    RigidBodySet<double> b;
    b.add({});
    b.set_kinematic(0);
    for (int i = 1; i <= boxes; ++i) {
      const double tilt = 0.02 * i;
      b.add({{0.01 * i, -(gap * i + hy * (2 * i - 1)), 0}, {}, {std::cos(tilt), 0, 0.6 * std::sin(tilt), 0.8 * std::sin(tilt)}, {},
             1, {(hy * hy + hz * hz) / 3, (hx * hx + hz * hz) / 3, (hx * hx + hy * hy) / 3}});
    }
    ForceModel<double> relaxing = forces(k);
    relaxing.add(LinearDrag{2}).add(AngularDrag{0.5});
    Stepper<double> s(relaxing, rk4, test::serial_options());
    s.advance(b, 2e-3, 15000);
    for (std::size_t i = 0; i < b.size(); ++i) b.set_velocity(i, {}), b.set_angular_momentum(i, {});
    return b;
  }
};

// Whether `steps` steps of h from the rest state, nudged, leave it far behind: the lowest box's
// speed and angular momentum.
bool blows_up(const Method& method, const ForceModel<double>& f, const RigidBodySet<double>& rest, double h) {
  RigidBodySet<double> b = rest;
  for (std::size_t i = 1; i < b.size(); ++i) b.set_velocity(i, {1e-6 * double(i), -2e-6, 1e-6}), b.set_angular_momentum(i, {1e-7, 2e-7, -1e-7});
  Stepper<double> s(f, method, test::serial_options());
  for (int k = 0; k < 2000; ++k) {
    s.step(b, h);
    const Vec3<double> v = b.centers().velocity(BoxChain::boxes);
    const Vec3<double> l = b.angular_momentum(BoxChain::boxes);
    if (!(std::abs(v[0]) + std::abs(v[1]) + std::abs(v[2]) + std::abs(l[0]) + std::abs(l[1]) + std::abs(l[2]) < 1)) return true;
  }
  return false;
}

}  // namespace

TEST_CASE("the predicted stable step of a chain of boxes is where it blows up", "[rigid][springs][stability]") {
  const RigidBodySet<double> rest = BoxChain::at_rest(2000);
  const ForceModel<double> f = BoxChain::forces(2000);
  const StiffnessEstimate e = estimate_stiffness(rest, f);
  CHECK(e.angle == Approx(std::numbers::pi / 2).margin(1e-3));  // undamped: an oscillation
  for (const Method* m : {&rk4, &symplectic_euler}) {
    INFO(m->name);
    const double predicted = largest_stable_step(*m, e);
    double stable = predicted / 2, unstable = predicted * 2;
    REQUIRE_FALSE(blows_up(*m, f, rest, stable));
    REQUIRE(blows_up(*m, f, rest, unstable));
    for (int k = 0; k < 20; ++k) {
      const double mid = std::sqrt(stable * unstable);
      (blows_up(*m, f, rest, mid) ? unstable : stable) = mid;
    }
    CHECK(stable == Approx(predicted).epsilon(0.05));  // measured: within 0.1%
  }
}

TEST_CASE("the rigid stiffness estimate finds a point spring's fastest rotational mode", "[rigid][springs][stability]") {
  // A body (moments 0.1, 0.2, 0.3) held at the point (0.3, 0.5, 0.2) by a spring of k = 1000:
  // the modes of M^-1 K, K = k A^T A with A = [1, -[p]x], are 31.62, 48.46 and 65.84 rad/s.
  RigidBodySet<double> b;
  b.add({{}, {}, {1, 0, 0, 0}, {}, 1, {0.1, 0.2, 0.3}});
  ForceModel<double> f;
  f.add(PointSpring{{0.3, 0.5, 0.2}, {0.3, 0.5, 0.2}, 1000, 0});
  for (int iterations : {20, 40, 120}) {
    INFO(iterations << " iterations");
    CHECK(estimate_stiffness(b, f, 0, iterations).magnitude == Approx(65.8408).epsilon(1e-4));
  }
  // Translation alone (a spring at the centre) is sqrt(k / m) = 31.62.
  ForceModel<double> central;
  central.add(PointSpring{{}, {}, 1000, 0});
  CHECK(estimate_stiffness(b, central).magnitude == Approx(std::sqrt(1000.0)).epsilon(1e-4));
}
