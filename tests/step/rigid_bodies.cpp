// Rigid bodies: conservation laws, the intermediate-axis flip, analytic rotations, orders of
// convergence, quaternion norm, inertia diagonalization, determinism.
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>

#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

RigidBodySet<double> one_body(const Vec3<double>& inertia, const Vec3<double>& l_world,
                              const Quat<double>& q = {1, 0, 0, 0}, double mass = 1) {
  RigidBodySet<double> set;
  set.add({{0, 0, 0}, {0, 0, 0}, q, l_world, mass, inertia});
  return set;
}

Quat<double> orientation(const RigidBodySet<double>& b) { return b.orientation(0); }

Vec3<double> body_frame_l(const RigidBodySet<double>& b) {
  const Quat<double> q = b.orientation(0);
  return rotate({q[0], -q[1], -q[2], -q[3]}, b.angular_momentum(0));
}

double rotational_energy(const RigidBodySet<double>& b) {
  const Vec3<double> lb = body_frame_l(b);
  double e = 0;
  for (int d = 0; d < 3; ++d) e += 0.5 * lb[d] * lb[d] * b.inv_inertia(d)[0];
  return e;
}

double norm(const Vec3<double>& v) { return std::hypot(v[0], v[1], v[2]); }

// Distance between orientations, blind to the sign of q (q and -q are one rotation).
double q_distance(const Quat<double>& a, const Quat<double>& b) {
  double plus = 0, minus = 0;
  for (int k = 0; k < 4; ++k) plus += (a[k] - b[k]) * (a[k] - b[k]), minus += (a[k] + b[k]) * (a[k] + b[k]);
  return std::sqrt(std::min(plus, minus));
}

Stepper<double> stepper(const Method& m, ForceModel<double> f = {}, bool renormalize = true) {
  StepperOptions o = test::serial_options();
  o.renormalize_quaternions = renormalize;
  return Stepper<double>(std::move(f), m, o);
}

const Vec3<double> kAsymmetric{3, 5, 9};
const Vec3<double> kFlipL{0, 2, 0.01};  // near the intermediate axis

}  // namespace

TEST_CASE("torque-free: |L| in the world frame is conserved by every method", "[rigid]") {
  for (const Method* m : builtin_methods) {
    RigidBodySet<double> b = one_body(kAsymmetric, kFlipL);
    auto s = stepper(*m);
    s.advance(b, 0.01, 2000);
    INFO(m->name);
    CHECK(norm(b.angular_momentum(0)) == Approx(norm(kFlipL)).epsilon(1e-14));
  }
}

TEST_CASE("torque-free: rk4 keeps the rotational energy, euler gains it", "[rigid]") {
  RigidBodySet<double> r = one_body(kAsymmetric, kFlipL), e = r;
  const double e0 = rotational_energy(r);
  auto rk = stepper(rk4), eu = stepper(euler);
  double worst = 0;
  for (int i = 0; i < 100; ++i) {  // 100 s at h = 1e-2, checked every second
    rk.advance(r, 0.01, 100);
    worst = std::max(worst, std::abs(rotational_energy(r) - e0) / e0);
  }
  eu.advance(e, 0.01, 10000);
  INFO("rk4 worst relative drift " << worst << ", euler " << rotational_energy(e) / e0 - 1);
  CHECK(worst < 1e-6);
  CHECK(rotational_energy(e) > 1.01 * e0);
}

namespace {

// Times at which the body-frame L_y changes sign, and its extreme values.
struct Flips {
  std::vector<double> crossings;
  double max_ly = 0, min_ly = 0;
};

Flips flips(double h, double duration) {
  RigidBodySet<double> b = one_body(kAsymmetric, kFlipL);
  auto s = stepper(rk4);
  Flips f;
  double prev = body_frame_l(b)[1];
  const auto steps = std::uint64_t(std::llround(duration / h));
  for (std::uint64_t k = 1; k <= steps; ++k) {
    s.step(b, h);
    const double ly = body_frame_l(b)[1];
    f.max_ly = std::max(f.max_ly, ly), f.min_ly = std::min(f.min_ly, ly);
    if ((ly < 0) != (prev < 0)) f.crossings.push_back(h * (double(k) - ly / (ly - prev)));
    prev = ly;
  }
  return f;
}

}  // namespace

TEST_CASE("the intermediate axis flips with a regular half-period", "[rigid][dzhanibekov]") {
  const Flips coarse = flips(1e-2, 300), reference = flips(1e-3, 300);
  REQUIRE(coarse.crossings.size() >= 4);
  REQUIRE(coarse.crossings.size() == reference.crossings.size());
  // L_y swings between about +2 and -2 (|L| = 2.000025).
  CHECK(coarse.max_ly == Approx(2).epsilon(1e-3));
  CHECK(coarse.min_ly == Approx(-2).epsilon(1e-3));
  std::vector<double> half_periods;
  for (std::size_t i = 1; i < coarse.crossings.size(); ++i) {
    half_periods.push_back(coarse.crossings[i] - coarse.crossings[i - 1]);
    const double ref = reference.crossings[i] - reference.crossings[i - 1];
    INFO("half-period " << i << ": " << half_periods.back() << " s, reference " << ref << " s");
    CHECK(half_periods.back() == Approx(ref).epsilon(1e-3));
    CHECK(half_periods.back() == Approx(half_periods.front()).epsilon(1e-2));  // regular
  }
  CHECK(half_periods.front() > 50);  // about 59 s for this perturbation
  CHECK(half_periods.front() < 70);
}

TEST_CASE("rotation about a principal axis follows the analytic quaternion", "[rigid]") {
  // omega about the body z axis, which starts along a tilted world axis: q(t) = r(t) q0 with
  // r the rotation by omega t about the world axis R(q0) z.
  const double w = 1.5, iz = 4, t = 2;
  const Quat<double> q0{std::cos(0.3), std::sin(0.3), 0, 0};
  const Vec3<double> axis = rotate(q0, {0, 0, 1});
  const Vec3<double> l{iz * w * axis[0], iz * w * axis[1], iz * w * axis[2]};
  const double a = w * t / 2;
  const Quat<double> r{std::cos(a), std::sin(a) * axis[0], std::sin(a) * axis[1], std::sin(a) * axis[2]};
  const Quat<double> exact = multiply(r, q0);
  for (const Method* m : builtin_methods) {
    RigidBodySet<double> b = one_body({2, 3, iz}, l, q0);
    auto s = stepper(*m);
    s.advance(b, t / 2000, 2000);
    INFO(m->name << " error " << q_distance(orientation(b), exact));
    CHECK(q_distance(orientation(b), exact) < (m->order == 4 ? 1e-12 : m->order == 2 ? 1e-5 : 2e-3));
    const Vec3<double> omega = b.angular_velocity(0);
    for (int d = 0; d < 3; ++d) CHECK(omega[d] == Approx(w * axis[d]).margin(1e-12));
  }
}

TEST_CASE("constant torque on a sphere: omega grows linearly, the angle quadratically", "[rigid]") {
  const double tau = 0.6, inertia = 2, t = 3;
  ForceModel<double> f;
  f.add(Torque{{0, tau, 0}});
  RigidBodySet<double> b = one_body({inertia, inertia, inertia}, {0, 0, 0});
  auto s = stepper(rk4, f);
  for (int k = 1; k <= 3; ++k) {
    s.advance(b, 0.001, 1000);
    const double time = k * t / 3;
    CHECK(b.angular_velocity(0)[1] == Approx(tau * time / inertia).epsilon(1e-12));
    const double angle = 0.5 * tau / inertia * time * time;
    const Quat<double> exact{std::cos(angle / 2), 0, std::sin(angle / 2), 0};
    CHECK(q_distance(orientation(b), exact) < 1e-10);
  }
}

namespace {

// Asymmetric body under a constant torque: orientation error at t = 2 against a fine rk4.
double rotation_error(const Method& m, int steps) {
  ForceModel<double> f;
  f.add(Torque{{0.3, -0.2, 0.5}});
  const Vec3<double> l0{1, 2, 0.5};
  auto run = [&](const Method& method, int n) {
    RigidBodySet<double> b = one_body(kAsymmetric, l0, {0.9, 0.1, 0.3, 0.2});
    auto s = stepper(method, f);
    s.advance(b, 2.0 / n, n);
    return orientation(b);
  };
  static const Quat<double> reference = run(rk4, 64 * 1600);
  return q_distance(run(m, steps), reference);
}

}  // namespace

TEST_CASE("each method converges at its order on a rotating body", "[rigid][convergence]") {
  for (const Method* m : builtin_methods) {
    const int n = m->order == 1 ? 400 : m->order == 2 ? 200 : 25;
    std::vector<double> h, err;
    for (int k : {1, 2, 4}) h.push_back(2.0 / (n * k)), err.push_back(rotation_error(*m, n * k));
    INFO(m->name << " errors " << err[0] << " " << err[1] << " " << err[2]);
    CHECK(test::fitted_order(h, err) == Approx(m->order).margin(0.15));
  }
}

TEST_CASE("the quaternion stays unit, and without renormalization Euler's grows", "[rigid]") {
  RigidBodySet<double> b = one_body(kAsymmetric, {1, 2, 0.5});
  auto s = stepper(euler);
  s.advance(b, 0.01, 5000);
  const Quat<double> q = orientation(b);
  CHECK(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) == Approx(1).epsilon(1e-15));

  // |q|^2 grows by exactly 1 + h^2 |omega|^2 / 4 per Euler step: (0, omega) q is orthogonal to q.
  RigidBodySet<double> raw = one_body(kAsymmetric, {1, 2, 0.5});
  auto free_run = stepper(euler, {}, false);
  const double h = 0.01;
  auto norm2 = [](const Quat<double>& q) { return q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]; };
  for (int k = 0; k < 300; ++k) {
    const double before = norm2(orientation(raw)), w = norm(raw.angular_velocity(0));
    free_run.step(raw, h);
    REQUIRE(norm2(orientation(raw)) / before == Approx(1 + h * h * w * w / 4).epsilon(1e-12));
  }
  CHECK(norm2(orientation(raw)) > 1.001);
}

namespace {

using Tensor = std::array<std::array<double, 3>, 3>;

// I = R diag(m) R^T.
Tensor turned(const Quat<double>& turn, const Vec3<double>& m) {
  Tensor tensor{};
  for (int a = 0; a < 3; ++a) {
    Vec3<double> axis{};
    axis[a] = 1;
    const Vec3<double> col = rotate(turn, axis);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) tensor[i][j] += m[a] * col[i] * col[j];
    }
  }
  return tensor;
}

}  // namespace

TEST_CASE("a full inertia tensor is diagonalized with the orientation adjusted", "[rigid]") {
  // A box with moments (1, 2, 3) x scale turned by a known rotation, at scales where the
  // Jacobi sums would overflow or underflow unless the tensor is scaled first.
  const Quat<double> turn{0.8, 0.2, -0.4, 0.4};  // unit: 0.64 + 0.04 + 0.16 + 0.16
  for (const double scale : {1.0, 2e307, 1e-300}) {
    INFO("scale " << scale);
    const Tensor tensor = turned(turn, {scale, 2 * scale, 3 * scale});
    const PrincipalFrame p = principal_frame(tensor);
    // The frame reproduces the tensor: R diag(m) R^T = I.
    const Tensor back = turned(p.rotation, p.moments);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) CHECK(back[i][j] / scale == Approx(tensor[i][j] / scale).margin(1e-12));
    }
    std::vector<double> moments(p.moments.begin(), p.moments.end());
    std::sort(moments.begin(), moments.end());
    CHECK(moments[0] / scale == Approx(1));
    CHECK(moments[2] / scale == Approx(3));
  }
  CHECK_THROWS_WITH(principal_frame({{{1, 0, 0}, {0, -1, 0}, {0, 0, 1}}}),
                    "inertia: the tensor is not positive definite");
  CHECK_THROWS_WITH(principal_frame({{{1, 0.5, 0}, {0, 1, 0}, {0, 0, 1}}}),
                    "inertia: the tensor is not symmetric");
  // Moments (1e308, 0, 1e308): singular, however large its entries.
  CHECK_THROWS_WITH(principal_frame({{{5e307, 5e307, 0}, {5e307, 5e307, 0}, {0, 0, 1e308}}}),
                    Catch::Contains("singular"));
  CHECK_THROWS_WITH(principal_frame({{{1, 1, 0}, {1, 1, 0}, {0, 0, 1}}}), Catch::Contains("singular"));
  CHECK_THROWS_WITH(principal_frame({{{1.5e308, 0, 0}, {0, 1.5e308, 1e308}, {0, 1e308, 1.5e308}}}),
                    Catch::Contains("overflows"));
}

TEST_CASE("bad rigid bodies are refused by name", "[rigid][errors]") {
  RigidBodySet<float> set;
  set.add({});
  CHECK_THROWS_WITH(set.add({{0, 0, 0}, {0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0}, 1, {1, 1, 1}}),
                    "rigid body 1: orientation quaternion is zero");
  CHECK_THROWS_WITH(set.add({{0, 0, 0}, {0, 0, 0}, {1, 0, 0, 0}, {0, 0, 0}, -1, {1, 1, 1}}),
                    Catch::StartsWith("rigid body 1: mass must be positive"));
  CHECK_THROWS_WITH(set.add({{0, 0, 0}, {0, 0, 0}, {1, 0, 0, 0}, {0, 0, 0}, 1, {0, 1, 1}}),
                    "rigid body 1: inertia moments must be positive");
  CHECK(set.size() == 1);
  ForceModel<float> f;
  f.add(Springs{{{0, 3, 1, 1, 0}}});  // spring pairs join rigid centres as they join particles
  Stepper<float> s(f, rk4, test::serial_options());
  CHECK_THROWS_WITH(s.step(set, 0.01f), "springs: a pair joins body 3, but the set has 1 bodies");
  CHECK_THROWS_WITH(energy(set, f), "springs: a pair joins body 3, but the set has 1 bodies");
  ForceModel<float> linked;
  linked.add(BodySprings{{{0, 2, {}, {}, 1, 1, 0}}});
  CHECK_THROWS_WITH(Stepper<float>(linked, rk4, test::serial_options()).step(set, 0.01f),
                    "body_springs: a spring joins body 2, but the set has 1 bodies");
  CHECK_THROWS_WITH(energy(set, linked), "body_springs: a spring joins body 2, but the set has 1 bodies");
}

namespace {

template <class T>
void check_rigid_determinism() {
  for (const Method* m : builtin_methods) {
    auto run = [&](StepperOptions o) {
      RigidBodySet<T> b = test::tumbling_cloud<T>(3000);
      Stepper<T>(test::rotational_terms<T>(), *m, o).advance(b, T(0.01), 10);
      REQUIRE(all_finite(b.centers()));
      return test::state_hash(b);
    };
    const std::uint64_t scalar = run(test::serial_options(Isa::scalar));
    for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
      if (!isa_available(isa)) continue;
      INFO(m->name << " on " << isa_name(isa));
      CHECK(run(test::serial_options(isa)) == scalar);
    }
    for (unsigned threads : {2u, 3u}) {
      TbbJobSystem tbb(threads);
      StepperOptions o;
      o.jobs = &tbb;
      o.workers = WorkerChoice::all;
      INFO(m->name << " on " << threads << " threads");
      CHECK(run(o) == scalar);
    }
  }
}

}  // namespace

TEST_CASE("rigid bodies: the same bits on every ISA and thread count (float)", "[rigid][determinism]") {
  check_rigid_determinism<float>();
}

TEST_CASE("rigid bodies: the same bits on every ISA and thread count (double)", "[rigid][determinism]") {
  check_rigid_determinism<double>();
}

TEST_CASE("particles ignore the rotational terms", "[rigid]") {
  const ForceModel<float> plain = test::all_local_terms<float>(), rotational = test::rotational_terms<float>();
  ParticleSet<float> a = test::cloud<float>(1000), b = a;
  Stepper<float>(plain, rk4, test::serial_options()).advance(a, 0.01f, 10);
  Stepper<float>(rotational, rk4, test::serial_options()).advance(b, 0.01f, 10);
  CHECK(test::state_hash(a) == test::state_hash(b));
}

TEST_CASE("a point force pushes the centre and turns the body", "[rigid]") {
  // Force F along y at body point (r, 0, 0) from rest: a = F/m, torque = r F about z (while
  // the turn, r F t^2 / 2I = 6e-4 rad, is small).
  const double r = 0.5, force = 2, m = 4, inertia = 1, t = 0.05;
  ForceModel<double> f;
  f.add(PointForce{{r, 0, 0}, {0, force, 0}});
  RigidBodySet<double> b = one_body({inertia, inertia, inertia}, {0, 0, 0}, {1, 0, 0, 0}, m);
  auto s = stepper(rk4, f);
  s.advance(b, 1e-5, 5000);
  CHECK(b.centers().velocity(0)[1] == Approx(force / m * t).epsilon(1e-9));
  CHECK(b.angular_momentum(0)[2] == Approx(r * force * t).epsilon(1e-6));
}
