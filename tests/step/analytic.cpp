// Each method against closed-form solutions: the error shrinks with h and is small at the
// finest step.
#include <catch2/catch.hpp>

#include <cmath>
#include <functional>

#include "support.hpp"

using namespace kinema;
using test::Snapshot;

namespace {

struct Exact {
  Vec3<double> x, v;
};

// Runs `method` to time `duration` at 3 step counts; returns the position+velocity errors.
std::vector<double> errors_at(const Method& method, const ForceModel<double>& forces,
                              const Vec3<double>& x0, const Vec3<double>& v0, double mass,
                              double duration, const Exact& exact, std::vector<int> counts) {
  std::vector<double> errors;
  for (int n : counts) {
    const auto s = test::run_one(method, forces, x0, v0, mass, duration / n, n);
    errors.push_back(test::distance(s.x, exact.x) + test::distance(s.v, exact.v));
  }
  return errors;
}

// Each halving of h divides the error by about 2^p (unless already at round-off), and the
// finest run is within 5% of the solution's scale. p is the method's order, or 1 for
// velocity Verlet under velocity-dependent forces (its second kick uses v at the half step).
void require_converges(const Method& method, const std::vector<double>& errors, double scale,
                       bool velocity_dependent) {
  INFO("method " << method.name << ": errors " << errors[0] << ", " << errors[1] << ", "
                 << errors[2]);
  const int order = velocity_dependent && &method == &velocity_verlet ? 1 : method.order;
  for (std::size_t i = 1; i < errors.size(); ++i) {
    if (errors[i - 1] < 1e-11) continue;
    CHECK(errors[i - 1] / errors[i] > 0.85 * std::pow(2.0, order));
  }
  CHECK(errors.back() < 0.05 * scale);
}

const std::vector<int> kCounts{400, 800, 1600};

}  // namespace

TEST_CASE("free fall matches x0 + v0 t + g t^2 / 2", "[analytic]") {
  ForceModel<double> f;
  f.add(Gravity{{0, -9.81, 0}});
  const double t = 2;
  const Exact exact{{1 + 3 * t, 2 + 4 * t - 0.5 * 9.81 * t * t, 0}, {3, 4 - 9.81 * t, 0}};
  for (const Method* m : builtin_methods) {
    auto e = errors_at(*m, f, {1, 2, 0}, {3, 4, 0}, 1, t, exact, kCounts);
    require_converges(*m, e, 20, false);
    // Constant acceleration: every method of order 2 or more is exact.
    if (m->order >= 2) CHECK(e.back() < 1e-11);
  }
}

TEST_CASE("linear drag approaches terminal velocity exponentially", "[analytic]") {
  // m dv/dt = m g - k v: v = vt + (v0 - vt) e^(-t k/m), vt = m g / k.
  const double m = 2, k = 0.8, g = -9.81, t = 3, tau = m / k, vt = m * g / k, v0 = 5;
  ForceModel<double> f;
  f.add(Gravity{{0, g, 0}}).add(LinearDrag{k});
  const double decay = std::exp(-t / tau);
  const Exact exact{{0, vt * t + (v0 - vt) * tau * (1 - decay), 0}, {0, vt + (v0 - vt) * decay, 0}};
  for (const Method* m_ : builtin_methods) {
    require_converges(*m_, errors_at(*m_, f, {0, 0, 0}, {0, v0, 0}, m, t, exact, kCounts),
                      std::abs(vt * t), true);
  }
}

TEST_CASE("undamped harmonic oscillator follows cos and sin", "[analytic]") {
  const double k = 4, m = 1, w = std::sqrt(k / m), t = 3, x0 = 1, v0 = 0.5;
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, k, 0});
  const Exact exact{{x0 * std::cos(w * t) + v0 / w * std::sin(w * t), 0, 0},
                    {-x0 * w * std::sin(w * t) + v0 * std::cos(w * t), 0, 0}};
  for (const Method* mt : builtin_methods) {
    require_converges(*mt, errors_at(*mt, f, {x0, 0, 0}, {v0, 0, 0}, m, t, exact, kCounts), 1,
                      false);
  }
}

TEST_CASE("damped harmonic oscillator decays as e^(-gamma t) with frequency omega_d",
          "[analytic]") {
  const double k = 4, c = 0.6, m = 1.5, t = 3, x0 = 1, v0 = -0.5;
  const double gamma = c / (2 * m), wd = std::sqrt(k / m - gamma * gamma);
  const double a = x0, b = (v0 + gamma * x0) / wd, e = std::exp(-gamma * t);
  const double cs = std::cos(wd * t), sn = std::sin(wd * t);
  const Exact exact{{e * (a * cs + b * sn), 0, 0},
                    {e * (-gamma * (a * cs + b * sn) + wd * (-a * sn + b * cs)), 0, 0}};
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, k, c});
  for (const Method* mt : builtin_methods) {
    require_converges(*mt, errors_at(*mt, f, {x0, 0, 0}, {v0, 0, 0}, m, t, exact, kCounts), 1,
                      true);
  }
}

TEST_CASE("float runs converge too, to float accuracy", "[analytic][float]") {
  // Undamped oscillator in float with rk4: error near float round-off, far below euler's.
  ForceModel<float> f;
  f.add(Spring{{0, 0, 0}, 4, 0});
  const double t = 3, w = 2;
  const auto rk = test::run_one<float>(rk4, f, {1, 0, 0}, {0, 0, 0}, 1, float(t / 300), 300);
  const auto eu = test::run_one<float>(euler, f, {1, 0, 0}, {0, 0, 0}, 1, float(t / 300), 300);
  const double exact = std::cos(w * t);
  CHECK(std::abs(rk.x[0] - exact) < 2e-5);
  CHECK(std::abs(eu.x[0] - exact) > 100 * std::abs(rk.x[0] - exact));
}

TEST_CASE("a kinematic body ignores forces and keeps its velocity", "[analytic]") {
  ForceModel<double> f = test::all_local_terms<double>();
  ParticleSet<double> bodies;
  bodies.add_kinematic({1, 2, 3}, {0.5, 0, -1});
  bodies.add({1, 2, 3}, {0.5, 0, -1}, 1);
  for (const Method* m : builtin_methods) {
    ParticleSet<double> b = bodies;
    Stepper<double> s(f, *m, test::serial_options());
    s.advance(b, 1.0 / 64, 64);  // h v is exact: the position is too
    CHECK(b.position(0) == Vec3<double>{1.5, 2, 2});
    CHECK(b.velocity(0) == Vec3<double>{0.5, 0, -1});
    CHECK(b.position(1) != b.position(0));
  }
}
