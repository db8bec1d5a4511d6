// Where methods fail: stability limits on x' = -lambda x, Euler's energy growth on the
// oscillator, and the circular orbit (Euler spirals out, rk4 holds, Verlet stays bounded).
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>

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
