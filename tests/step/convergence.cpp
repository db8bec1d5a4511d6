// Measured orders of convergence from errors at h, h/2, h/4, and the classic RK4 typo
// (k4 = f(x + h k3 / 2)) caught by the same measurement.
#include <catch2/catch.hpp>

#include <cmath>

#include "support.hpp"

using namespace kinema;

namespace {

// Damped oscillator (k = 4, c = 0.5, m = 1) from x = 1 over 2 s: global error at the end.
double oscillator_error(const Method& method, int steps, double damping, bool staged = false) {
  const double k = 4, t = 2, gamma = damping / 2, wd = std::sqrt(k - gamma * gamma);
  const double e = std::exp(-gamma * t), b = gamma / wd;
  const double x = e * (std::cos(wd * t) + b * std::sin(wd * t));
  const double v = e * (-gamma * (std::cos(wd * t) + b * std::sin(wd * t)) +
                        wd * (-std::sin(wd * t) + b * std::cos(wd * t)));
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, k, damping});
  StepperOptions o = test::serial_options();
  o.force_staged = staged;
  const auto s = test::run_one<double>(method, f, {1, 0, 0}, {0, 0, 0}, 1, t / steps, steps, o);
  return std::hypot(s.x[0] - x, s.v[0] - v);
}

// Step counts in each method's asymptotic range, well above round-off.
int base_steps(int order) { return order == 1 ? 2000 : order == 2 ? 400 : 50; }

double measured_order(const Method& method, double damping, bool staged = false) {
  const int n = base_steps(method.order);
  std::vector<double> h, err;
  for (int k : {1, 2, 4}) {
    h.push_back(2.0 / (n * k));
    err.push_back(oscillator_error(method, n * k, damping, staged));
  }
  INFO(method.name << " errors " << err[0] << " " << err[1] << " " << err[2]);
  // Each halving on its own gives the same order as the fit.
  CHECK(std::log2(err[0] / err[1]) == Approx(std::log2(err[1] / err[2])).margin(0.1));
  return test::fitted_order(h, err);
}

}  // namespace

TEST_CASE("each method converges at its nominal order", "[convergence]") {
  for (const Method* m : builtin_methods) {
    // Velocity Verlet's second kick sees the half-step velocity: its order is 2 only for
    // velocity-independent forces, so it is measured undamped (see the next test).
    const double damping = m == &velocity_verlet ? 0.0 : 0.5;
    INFO("method " << m->name);
    CHECK(measured_order(*m, damping) == Approx(m->order).margin(0.1));
  }
}

TEST_CASE("velocity verlet drops to first order with velocity-dependent forces",
          "[convergence]") {
  CHECK(measured_order(velocity_verlet, 0.0) == Approx(2).margin(0.1));
  CHECK(measured_order(velocity_verlet, 0.5) == Approx(1).margin(0.15));
}

TEST_CASE("the staged path converges at the same orders", "[convergence]") {
  for (const Method* m : builtin_methods) {
    INFO("method " << m->name);
    const double damping = m == &velocity_verlet ? 0.0 : 0.5;
    CHECK(measured_order(*m, damping, true) == Approx(m->order).margin(0.1));
  }
}

TEST_CASE("the RK4 typo k4 = f(x + h k3/2) is caught as a loss of order", "[convergence]") {
  Method typo = rk4;
  typo.name = "rk4_typo";
  typo.tableau.a[3][2] = 0.5;
  REQUIRE(builtin_index(typo) == -1);  // runs on the staged path, from its tableau
  // sum b_i c_i = 5/12 instead of 1/2: the second-order condition fails, first order remains.
  const double order = test::fitted_order(
      {2.0 / 400, 2.0 / 800, 2.0 / 1600},
      {oscillator_error(typo, 400, 0.5), oscillator_error(typo, 800, 0.5),
       oscillator_error(typo, 1600, 0.5)});
  CHECK(order == Approx(1).margin(0.15));
  CHECK(measured_order(rk4, 0.5, true) == Approx(4).margin(0.1));
}

TEST_CASE("a user tableau (Ralston's RK2) runs and converges at order 2", "[convergence]") {
  Method ralston{"ralston", MethodKind::runge_kutta, 2,
                 {2, {{{}, {2.0 / 3}}}, {0.25, 0.75}, {0, 2.0 / 3}}, {}};
  CHECK(measured_order(ralston, 0.5) == Approx(2).margin(0.1));
}

TEST_CASE("a user tableau whose first weight is tiny keeps its other stages exact", "[convergence]") {
  // Midpoint with a first stage nudged by 1e-39: in float that weight is subnormal, and no
  // other row may be scaled by it.
  const Method nudged{"nudged_midpoint", MethodKind::runge_kutta, 2,
                      {3, {{{}, {1e-39}, {0, 0.5}}}, {0, 0, 1}, {0, 1e-39, 0.5}}, {}};
  ForceModel<float> f;
  f.add(Spring{{0, 0, 0}, 4, 0.5});
  const auto a = test::run_one<float>(nudged, f, {1, 0, 0}, {0, 0, 0}, 1, 0.01f, 100);
  const auto b = test::run_one<float>(midpoint, f, {1, 0, 0}, {0, 0, 0}, 1, 0.01f, 100);
  CHECK(test::distance(a.x, b.x) < 1e-6);
  CHECK(test::distance(a.v, b.v) < 1e-6);
}

TEST_CASE("a user tableau with an all-zero row reads the bodies' own state there", "[convergence]") {
  // Two stages at t0 (c = 0, a row of zeros), weights 1/2 + 1/2: Euler in disguise.
  const Method twice{"twice_euler", MethodKind::runge_kutta, 1, {2, {{{}, {0}}}, {0.5, 0.5}, {0, 0}}, {}};
  ForceModel<double> f;
  f.add(Gravity{{0, -9.81, 0}}).add(LinearDrag{0.3});
  const auto a = test::run_one<double>(twice, f, {0, 0, 0}, {1, 0, 0}, 1, 0.1, 10);
  const auto b = test::run_one<double>(euler, f, {0, 0, 0}, {1, 0, 0}, 1, 0.1, 10);
  CHECK(test::distance(a.x, b.x) < 1e-15);
  CHECK(test::distance(a.v, b.v) < 1e-15);
}

namespace {

// The e = 0.6 Kepler orbit over 4 s (a nonlinear force: every order condition counts), in
// double, against Kepler's equation.
std::vector<double> kepler_errors(const Method& method, std::uint64_t steps) {
  const Scene scene = load_scene(KINEMA_SCENES "/kepler_eccentric.json");
  const double duration = scene.dt * double(scene.steps);
  const BodyStates exact = *analytic_states(scene, duration);
  std::vector<double> errors;
  for (std::uint64_t k : {1, 2, 4}) errors.push_back(state_error(simulate(scene, method, steps * k, duration), exact));
  return errors;
}

double kepler_order(const Method& method, std::uint64_t steps) {
  const std::vector<double> err = kepler_errors(method, steps);
  INFO(method.name << " errors " << err[0] << " " << err[1] << " " << err[2]);
  CHECK(std::log2(err[0] / err[1]) == Approx(std::log2(err[1] / err[2])).margin(0.25));
  return test::fitted_order({4.0 / double(steps), 2.0 / double(steps), 1.0 / double(steps)}, err);
}

// A pair's embedded solution as a method of its own: the weights b_hat in place of b.
Method embedded_solution(const Method& pair) {
  Method m = pair;
  m.name = "embedded";
  m.order = pair.embedded_order;
  m.tableau.b = pair.tableau.b_hat;
  m.tableau.b_hat = {};
  m.embedded_order = 0;
  return m;
}

}  // namespace

TEST_CASE("the embedded pairs and rk6 converge at orders 3 and 2, 5 and 4, and 6 on an orbit",
          "[convergence]") {
  CHECK(kepler_order(bs3, 400) == Approx(3).margin(0.1));
  CHECK(kepler_order(embedded_solution(bs3), 400) == Approx(2).margin(0.1));
  CHECK(kepler_order(dopri5, 200) == Approx(5).margin(0.25));
  CHECK(kepler_order(embedded_solution(dopri5), 1000) == Approx(4).margin(0.25));
  CHECK(kepler_order(rk6, 100) == Approx(6).margin(0.2));
}
