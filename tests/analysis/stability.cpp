// Where methods fail: stability limits on x' = -lambda x, Euler's energy growth on the
// oscillator, and the circular orbit (Euler spirals out, rk4 holds, Verlet stays bounded).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>

#include "kinema/stability.hpp"
#include "support.hpp"

using namespace kinema;

namespace {

// Linear drag alone on a unit mass gives v' = -lambda v with lambda = k: the velocity is
// the test equation. Stable when |v| has not grown after many steps.
bool stable(const Method& method, double h_lambda) {
  ForceModel<double> f;
  f.add(LinearDrag{1.0});
  const auto s = test::run_one<double>(method, f, {0, 0, 0}, {1, 0, 0}, 1, h_lambda, 4000);
  return std::isfinite(s.v[0]) && std::abs(s.v[0]) <= 1.0;
}

double stability_limit(const Method& method) {
  double lo = 0.5, hi = 4.0;  // stable at lo, unstable at hi for every explicit method here
  REQUIRE(stable(method, lo));
  REQUIRE_FALSE(stable(method, hi));
  while (hi - lo > 1e-6) {
    const double mid = 0.5 * (lo + hi);
    (stable(method, mid) ? lo : hi) = mid;
  }
  return lo;
}

double energy_of(const ParticleSet<double>& b, const ForceModel<double>& f) {
  return energy(b, f).total();
}

}  // namespace

TEST_CASE("largest stable h*lambda: 2 for euler and midpoint, 2.785 for rk4", "[stability]") {
  CHECK(stability_limit(euler) == Approx(2.0).epsilon(1e-4));
  CHECK(stability_limit(midpoint) == Approx(2.0).epsilon(1e-4));
  CHECK(stability_limit(heun) == Approx(2.0).epsilon(1e-4));
  CHECK(stability_limit(rk4) == Approx(2.785).epsilon(0.005));
}

TEST_CASE("explicit Euler's oscillator energy grows by exactly 1 + h^2 w^2 per step",
          "[stability]") {
  const double k = 9, h = 0.01, w2 = k;  // unit mass: w^2 = k
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, k, 0});
  ParticleSet<double> b;
  b.add({1, 0, 0}, {0.5, 0, 0}, 1);
  Stepper<double> s(f, euler, test::serial_options());
  double e = energy_of(b, f);
  for (int i = 0; i < 200; ++i) {
    s.step(b, h);
    const double next = energy_of(b, f);
    REQUIRE(next / e == Approx(1 + h * h * w2).epsilon(1e-12));
    e = next;
  }
}

namespace {

struct OrbitRun {
  double max_radius_error = 0;  // |r - 1|, over the whole run
  double max_energy_error = 0;  // |E - E0| / |E0|
  double first_energy_error = 0, last_energy_error = 0;  // maxima over the first/last 10%
};

// Unit circular orbit around mu = 1 (period 2 pi), `orbits` orbits at 100 steps each.
OrbitRun circular_orbit(const Method& method, int orbits) {
  ForceModel<double> f;
  f.add(Central{{0, 0, 0}, 1});
  ParticleSet<double> b;
  b.add({1, 0, 0}, {0, 1, 0}, 1);
  Stepper<double> s(f, method, test::serial_options());
  const double e0 = energy_of(b, f), h = 2 * std::numbers::pi / 100;
  const int steps = 100 * orbits, tenth = steps / 10;
  OrbitRun run;
  for (int i = 1; i <= steps; ++i) {
    s.step(b, h);
    const auto x = b.position(0);
    const double r = std::hypot(x[0], x[1], x[2]);
    const double de = std::abs(energy_of(b, f) - e0) / std::abs(e0);
    run.max_radius_error = std::max(run.max_radius_error, std::abs(r - 1));
    run.max_energy_error = std::max(run.max_energy_error, de);
    if (i <= tenth) run.first_energy_error = std::max(run.first_energy_error, de);
    if (i > steps - tenth) run.last_energy_error = std::max(run.last_energy_error, de);
  }
  return run;
}

}  // namespace

TEST_CASE("on a circular orbit euler spirals out, rk4 holds the radius", "[stability][orbit]") {
  const OrbitRun e = circular_orbit(euler, 10);
  INFO("euler radius error " << e.max_radius_error);
  CHECK(e.max_radius_error > 0.10);  // "off to Neptune"
  const OrbitRun r = circular_orbit(rk4, 10);
  INFO("rk4 radius error " << r.max_radius_error);
  CHECK(r.max_radius_error < 1e-4);
}

TEST_CASE("velocity verlet's orbit energy error stays bounded over 1000 orbits",
          "[stability][orbit]") {
  const OrbitRun v = circular_orbit(velocity_verlet, 1000);
  INFO("verlet energy error: first 100 orbits " << v.first_energy_error << ", last 100 "
                                                << v.last_energy_error);
  CHECK(v.max_energy_error < 1e-3);
  // No secular drift: the last hundred orbits are no worse than the first hundred.
  CHECK(v.last_energy_error < 1.05 * v.first_energy_error);
  // rk4 at the same step drifts steadily instead (dissipative, not symplectic).
  const OrbitRun r = circular_orbit(rk4, 1000);
  CHECK(r.last_energy_error > 5 * r.first_energy_error);
}

namespace {

// The largest stable h found by running: `force` on one unit-mass body started at x = 1,
// v = 1, 4000 steps; stable while |x| stays under 10 (an unstable velocity drags x along).
double bisected_limit(const Method& method, const ForceModel<double>& forces, double guess) {
  const auto holds = [&](double h) {
    const auto s = test::run_one<double>(method, forces, {1, 0, 0}, {1, 0, 0}, 1, h, 4000);
    return std::isfinite(s.x[0]) && std::isfinite(s.v[0]) && std::abs(s.x[0]) < 10;
  };
  double lo = guess * 0.5, hi = guess * 1.5;
  REQUIRE(holds(lo));
  REQUIRE_FALSE(holds(hi));
  while (hi - lo > 1e-5 * guess) {
    const double mid = 0.5 * (lo + hi);
    (holds(mid) ? lo : hi) = mid;
  }
  return lo;
}

StiffnessEstimate estimate_of(const ForceModel<double>& forces) {
  ParticleSet<double> b;
  b.add({1, 0, 0}, {1, 0, 0}, 1);
  return estimate_stiffness(b, forces);
}

}  // namespace

TEST_CASE("stability limits on the real and imaginary axes, from each method's coefficients", "[stability]") {
  const auto limits = [](const Method& m) { return stability_limits(m); };
  CHECK(limits(euler).real_axis == Approx(2).epsilon(1e-6));
  CHECK(limits(euler).imaginary_axis < 1e-3);  // no stable step on an undamped oscillation
  CHECK(limits(midpoint).real_axis == Approx(2).epsilon(1e-6));
  CHECK(limits(rk4).real_axis == Approx(2.78529).epsilon(1e-4));
  CHECK(limits(rk4).imaginary_axis == Approx(2 * std::sqrt(2.0)).epsilon(1e-6));
  CHECK(limits(bs3).real_axis == Approx(2.5127).epsilon(1e-3));
  CHECK(limits(bs3).imaginary_axis == Approx(std::sqrt(3.0)).epsilon(1e-6));
  CHECK(limits(dopri5).real_axis == Approx(3.3059).epsilon(1e-3));
  CHECK(limits(symplectic_euler).imaginary_axis == Approx(2).epsilon(1e-6));
  CHECK(limits(velocity_verlet).imaginary_axis == Approx(2).epsilon(1e-6));
  // A kick at the half-step velocity: drag is damped twice per step, (1 - h k / 2)^2.
  CHECK(limits(velocity_verlet).real_axis == Approx(4).epsilon(1e-6));
}

TEST_CASE("stable steps and growth at rates whose square overflows double", "[stability]") {
  // An undamped oscillation at 1e200 /s: rk4's edge is 2 sqrt(2) / 1e200 as at any rate, and a
  // step far past it grows (it read as no stable step at all, and a growth of NaN).
  const double pi = std::numbers::pi;
  for (double rate : {1e3, 1e200}) {
    INFO(rate);
    const StiffnessEstimate oscillation{rate, pi / 2, 0};
    CHECK(largest_stable_step(rk4, oscillation) * rate == Approx(2 * std::sqrt(2.0)).epsilon(1e-6));
    CHECK(growth_per_step(rk4, oscillation, 1 / rate) == Approx(growth_per_step(rk4, {1, pi / 2, 0}, 1)).epsilon(1e-9));
    CHECK(growth_per_step(rk4, oscillation, 1e-2 * 1e300 / rate) == std::numeric_limits<double>::infinity());
  }
  // Damping at 1e300 /s: euler's edge 2 / 1e300; a step of 0.01 grows past what double holds.
  const StiffnessEstimate damping{1e300, 0, 0};
  CHECK(largest_stable_step(euler, damping) * 1e300 == Approx(2).epsilon(1e-6));
  CHECK(growth_per_step(rk4, damping, 0.01) == std::numeric_limits<double>::infinity());
}

TEST_CASE("the stiffness estimate of an undamped spring is its angular frequency, an oscillation", "[stability]") {
  // Two bodies on a spring (omega^2 = k (m1 + m2) / (m1 m2)), with other bodies on a softer
  // anchor spring: the estimate finds the fastest mode.
  ParticleSet<double> b;
  b.add({0, 0, 0}, {0.1, 0, 0}, 2);
  b.add({1, 0.2, 0}, {0, 0, 0}, 3);
  for (int i = 0; i < 50; ++i) b.add({double(i), 2, 0}, {0, 0.1, 0}, 1);
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, 1, 0});
  f.add(Springs{{{0, 1, 1, 600, 0}}});
  const StiffnessEstimate e = estimate_stiffness(b, f);
  const double omega = std::sqrt(1 + 600.0 * 5 / 6);  // the anchor adds k = 1 to each end
  CHECK(e.magnitude == Approx(omega).epsilon(0.01));
  CHECK(e.angle == Approx(std::numbers::pi / 2).margin(0.02));
  ParticleSet<float> bf;
  bf.add({0, 0, 0}, {0.1f, 0, 0}, 2);
  bf.add({1, 0.2f, 0}, {0, 0, 0}, 3);
  ForceModel<float> ff;
  ff.add(Spring{{0, 0, 0}, 1, 0});
  ff.add(Springs{{{0, 1, 1, 600, 0}}});
  CHECK(estimate_stiffness(bf, ff).magnitude == Approx(omega).epsilon(0.01));  // in float too
}

TEST_CASE("a stiffness estimate that is not finite never reads as a state without modes", "[stability][errors]") {
  // A NaN magnitude once read as 0: every step stable, no growth.
  ForceModel<float> f;
  f.add(Spring{{0, 0, 0}, 100, 0});
  ParticleSet<float> overflowing;  // its spring force, 100 x 1e37, overflows float
  overflowing.add({1, 0, 0}, {0, 0, 0}, 1);
  overflowing.add({1e37f, 0, 0}, {0, 0, 0}, 1);
  ParticleSet<float> gone_bad;
  gone_bad.add({1, 0, 0}, {0, 0, 0}, 1);
  gone_bad.add({0, 0, 0}, {0, 0, 0}, 1);
  gone_bad.px()[1] = std::numeric_limits<float>::quiet_NaN();  // through the arrays
  for (const ParticleSet<float>* set : {&overflowing, &gone_bad}) {
    const StiffnessEstimate e = estimate_stiffness(*set, f);
    CHECK_FALSE(std::isfinite(e.magnitude));
    if (std::isnan(e.magnitude)) {
      CHECK_THROWS_WITH(largest_stable_step(rk4, e), "largest_stable_step: the estimate's magnitude is NaN");
    } else {
      CHECK(largest_stable_step(rk4, e) == 0);  // an infinitely fast mode: no step holds it
    }
  }
  const StiffnessEstimate nan{std::numeric_limits<double>::quiet_NaN(), 1, 0};
  CHECK_THROWS_WITH(largest_stable_step(rk4, nan), "largest_stable_step: the estimate's magnitude is NaN");
  CHECK_THROWS_WITH(growth_per_step(euler, nan, 1), "growth_per_step: the estimate's magnitude is NaN");
  overflowing.px()[1] = 1;  // finite again: an oscillation at omega = 10, rk4 stable to 2 sqrt(2) / 10
  CHECK(largest_stable_step(rk4, estimate_stiffness(overflowing, f)) == Approx(0.2828).epsilon(0.01));
}

TEST_CASE("predicted stable steps match bisected blow-ups within 2%", "[prediction]") {
  // An undamped oscillator (omega = 20): imaginary-axis limits.
  ForceModel<double> spring;
  spring.add(Spring{{0, 0, 0}, 400, 0});
  const StiffnessEstimate oscillation = estimate_of(spring);
  for (const Method* m : {&rk4, &bs3, &symplectic_euler, &velocity_verlet}) {
    INFO(m->name << " on an oscillation");
    const double predicted = largest_stable_step(*m, oscillation);
    CHECK(bisected_limit(*m, spring, predicted) == Approx(predicted).epsilon(0.02));
  }
  CHECK(largest_stable_step(euler, oscillation) < 1e-3 / 20);
  // Drag at rate 50: real-axis limits.
  ForceModel<double> drag;
  drag.add(LinearDrag{50});
  const StiffnessEstimate damping = estimate_of(drag);
  CHECK(damping.magnitude == Approx(50).epsilon(0.01));
  CHECK(damping.angle < 1e-3);
  for (const Method* m : {&euler, &midpoint, &heun, &rk4, &bs3, &dopri5, &rk6, &symplectic_euler, &velocity_verlet}) {
    INFO(m->name << " on damping");
    const double predicted = largest_stable_step(*m, damping);
    CHECK(bisected_limit(*m, drag, predicted) == Approx(predicted).epsilon(0.02));
  }
  // A damped oscillator (omega = 20, damping ratio 0.3): off both axes.
  ForceModel<double> damped;
  damped.add(Spring{{0, 0, 0}, 400, 12});
  const StiffnessEstimate mixed = estimate_of(damped);
  CHECK(mixed.magnitude == Approx(20).epsilon(0.01));
  for (const Method* m : {&euler, &rk4, &dopri5, &symplectic_euler}) {
    INFO(m->name << " on a damped oscillation");
    const double predicted = largest_stable_step(*m, mixed);
    CHECK(bisected_limit(*m, damped, predicted) == Approx(predicted).epsilon(0.02));
  }
}
