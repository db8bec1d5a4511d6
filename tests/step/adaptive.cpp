// The error-controlled driver: tolerances met against Kepler's equation at e = 0.9, cheaper
// than fixed-step rk4 there, the same steps as Boost.Odeint's controlled dopri5, the same
// steps on every thread count and ISA, rejected steps that leave nothing behind.
#include <catch2/catch.hpp>

#include <functional>

#include <array>
#include <random>
#include <stdexcept>
#include <bit>
#include <cmath>
#include <functional>
#include <numbers>
#include <vector>

#include <boost/numeric/odeint.hpp>

#include "kernels/reductions.hpp"
#include "kinema/stability.hpp"
#include "support.hpp"

using namespace kinema;

namespace {

// The e = 0.9 orbit (a = 1, mu = 1) from periapsis r = 0.1, speed sqrt(19): after one
// period it is back where it started.
constexpr double kE = 0.9, kPeriapsis = 1 - kE;
const double kSpeed = std::sqrt((1 + kE) / kPeriapsis);
constexpr double kPeriod = 2 * std::numbers::pi;

ForceModel<double> attractor() {
  ForceModel<double> f;
  f.add(Central{{0, 0, 0}, 1});
  return f;
}

ParticleSet<double> at_periapsis() {
  ParticleSet<double> b;
  b.add({kPeriapsis, 0, 0}, {0, kSpeed, 0}, 1);
  return b;
}

double error_after_one_period(const ParticleSet<double>& b) {
  const auto x = b.position(0), v = b.velocity(0);
  return std::hypot(x[0] - kPeriapsis, x[1], x[2]) + std::hypot(v[0], v[1] - kSpeed, v[2]);
}

struct OrbitRun {
  AdaptiveStats stats;
  double error;
};

OrbitRun adaptive_orbit(const Method& m, double tol, StepperOptions o = test::serial_options()) {
  ParticleSet<double> b = at_periapsis();
  Stepper<double> stepper(attractor(), m, o);
  const AdaptiveStats stats = stepper.advance_to(b, kPeriod, {tol, tol});
  CHECK(stepper.time() == kPeriod);
  return {stats, error_after_one_period(b)};
}

double rk4_orbit_error(std::uint64_t steps) {
  ParticleSet<double> b = at_periapsis();
  Stepper<double>(attractor(), rk4, test::serial_options()).advance(b, kPeriod / double(steps), steps);
  return error_after_one_period(b);
}

}  // namespace

TEST_CASE("dopri5 and bs3: the final error on the e = 0.9 orbit is proportional to the tolerance",
          "[adaptive]") {
  // Local error control: each step's error estimate is held under the tolerance, and the
  // error at the end is a fixed multiple of it (large here: a timing error at the fast
  // periapsis pass is a large error in position), so a hundred times tighter tolerance
  // gives a hundred times less error.
  for (const Method* m : {&dopri5, &bs3}) {
    const double loose = m == &dopri5 ? 1e-6 : 1e-5;
    std::vector<OrbitRun> runs;
    for (double tol : {loose, loose / 100, loose / 10000}) runs.push_back(adaptive_orbit(*m, tol));
    for (std::size_t k = 0; k + 1 < runs.size(); ++k) {
      INFO(m->name << ": errors " << runs[k].error << " then " << runs[k + 1].error << ", steps "
                   << runs[k].stats.accepted << " then " << runs[k + 1].stats.accepted);
      CHECK(runs[k].error / runs[k + 1].error > 30);
      CHECK(runs[k].error / runs[k + 1].error < 300);
      CHECK(runs[k + 1].stats.accepted > runs[k].stats.accepted);
    }
    // The close pass at periapsis takes steps far shorter than the slow arc at apoapsis.
    CHECK(runs.back().stats.largest_step > 20 * runs.back().stats.smallest_step);
  }
}

TEST_CASE("dopri5's steps cost fewer force evaluations than fixed-step rk4 at the same error", "[driver]") {
  const OrbitRun a = adaptive_orbit(dopri5, 1e-10);
  // The fewest rk4 steps that reach the adaptive run's error (found by doubling, then bisection).
  std::uint64_t lo = 1, hi = 2;
  while (rk4_orbit_error(hi) > a.error) lo = hi, hi *= 2;
  while (hi - lo > 1) {
    const std::uint64_t mid = (lo + hi) / 2;
    (rk4_orbit_error(mid) > a.error ? lo : hi) = mid;
  }
  INFO("dopri5: error " << a.error << " with " << a.stats.evaluations << " evaluations; rk4 needs " << hi
                        << " steps = " << 4 * hi << " evaluations");
  CHECK(a.stats.evaluations * 3 < 4 * hi);
}

TEST_CASE("dopri5 counts six evaluations per attempt (first same as last) and bs3 three", "[adaptive]") {
  for (const Method* m : {&dopri5, &bs3}) {
    const OrbitRun a = adaptive_orbit(*m, 1e-9);
    INFO(m->name << ": " << a.stats.accepted << " accepted, " << a.stats.rejected << " rejected");
    // One evaluation for the first guess, which the first attempt reuses.
    const std::uint64_t per_attempt = std::uint64_t(m->tableau.stages - 1);
    CHECK(a.stats.evaluations == 1 + per_attempt * (a.stats.accepted + a.stats.rejected));
  }
}

TEST_CASE("the driver takes about the steps Boost.Odeint's controlled dopri5 takes, to an error of the same order",
          "[driver][odeint]") {
  namespace odeint = boost::numeric::odeint;
  using State = std::array<double, 4>;  // x, y, vx, vy
  const auto kepler = [](const State& s, State& ds, double) {
    const double r = std::hypot(s[0], s[1]), r3 = r * r * r;
    ds = {s[2], s[3], -s[0] / r3, -s[1] / r3};
  };
  for (double tol : {1e-6, 1e-9, 1e-12}) {
    INFO("tolerance " << tol);
    State s{kPeriapsis, 0, 0, kSpeed};
    std::uint64_t odeint_steps = 0;
    odeint::integrate_adaptive(odeint::make_controlled<odeint::runge_kutta_dopri5<State>>(tol, tol), kepler, s, 0.0,
                               kPeriod, 1e-4, [&](const State&, double) { ++odeint_steps; });
    --odeint_steps;  // the observer also sees the start
    const double odeint_error = std::hypot(s[0] - kPeriapsis, s[1]) + std::hypot(s[2], s[3] - kSpeed);
    ParticleSet<double> b = at_periapsis();
    Stepper<double> stepper(attractor(), dopri5, test::serial_options());
    Tolerances t{tol, tol};
    t.initial_step = 1e-4;
    const AdaptiveStats stats = stepper.advance_to(b, kPeriod, t);
    const double error = error_after_one_period(b);
    INFO("kinema: " << stats.accepted << " steps, error " << error << "; odeint: " << odeint_steps << " steps, error "
                    << odeint_error);
    CHECK(double(stats.accepted) < 2.0 * double(odeint_steps));
    CHECK(double(odeint_steps) < 2.0 * double(stats.accepted));
    CHECK(error < 10 * odeint_error);
    CHECK(odeint_error < 10 * error);
  }
}

TEST_CASE("the accepted steps are the same on every thread count, job system and ISA", "[driver][determinism]") {
  // Every local term and a chain of springs (so stages are jobs of their own too): the hash
  // covers the final state and the step statistics.
  const auto run = [](const StepperOptions& o, std::size_t n) {
    std::uint64_t hash = 0;
    for (const bool coupled : {false, true}) {
      ForceModel<float> f = test::all_local_terms<float>();
      if (coupled) {
        Springs chain;
        for (std::uint32_t i = 1; i < std::uint32_t(n); ++i) chain.pairs.push_back({i - 1, i, 0.5, 20, 0.1});
        f.add(chain);
      }
      ParticleSet<float> b = test::cloud<float>(n);
      Stepper<float> stepper(f, dopri5, o);
      const AdaptiveStats s = stepper.advance_to(b, 0.5, {1e-4, 1e-4});
      REQUIRE(s.accepted > 3);
      hash = hash * 31 + (test::state_hash(b) ^ (s.accepted * 1000003 + s.rejected * 10007 + s.evaluations) ^
                          std::bit_cast<std::uint64_t>(s.smallest_step));
    }
    return hash;
  };
  test::check_same_bits_everywhere(run, 300, 5000);
}

TEST_CASE("a step too long for the tolerance is taken back and leaves nothing behind", "[adaptive]") {
  // Undamped oscillator w = 2 from x = 1: exact x = cos 2t. A first step of 5 s is absurd.
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, 4, 0});
  ParticleSet<double> b;
  b.add({1, 0, 0}, {0, 0, 0}, 1);
  Stepper<double> stepper(f, dopri5, test::serial_options());
  Tolerances t{1e-10, 1e-10};
  t.initial_step = 5;
  const AdaptiveStats s = stepper.advance_to(b, 3, t);
  CHECK(s.rejected >= 3);
  // Seven for the first attempt; every later one, after a rejection too, starts from an
  // evaluation it already has.
  CHECK(s.evaluations == 7 + 6 * (s.accepted + s.rejected - 1));
  CHECK(std::abs(b.position(0)[0] - std::cos(6.0)) < 1e-8);
  CHECK(std::abs(b.velocity(0)[0] + 2 * std::sin(6.0)) < 1e-8);
}

TEST_CASE("advance_to refuses methods without a pair, bad tolerances and times in the past", "[adaptive][errors]") {
  ParticleSet<double> b = at_periapsis();
  Stepper<double> fixed(attractor(), rk4, test::serial_options());
  CHECK_THROWS_WITH(fixed.advance_to(b, 1, {}), Catch::Contains("needs a method with an embedded pair"));
  Stepper<double> s(attractor(), dopri5, test::serial_options());
  CHECK_THROWS_WITH(s.advance_to(b, 1, {0, 0}), Catch::Contains("not both 0"));
  CHECK_THROWS_WITH(s.advance_to(b, 1, {-1, 1e-6}), Catch::Contains("rtol and atol"));
  // Below the round-off of one step (rtol 1e-24 used to take hundreds of millions of steps,
  // 1e-30 never ended): refused before any.
  for (const double tiny : {1e-24, 1e-30}) {
    CHECK_THROWS_WITH(s.advance_to(b, 1, {tiny, tiny}), Catch::Contains("far below the round-off of one step in double"));
  }
  CHECK(s.time() == 0);
  ParticleSet<float> f;
  f.add({3, 0, 0}, {0, 1, 0}, 1);
  ForceModel<float> pull;
  pull.add(Central{{0, 0, 0}, 1});
  Stepper<float> in_float(pull, dopri5, test::serial_options());
  CHECK_THROWS_WITH(in_float.advance_to(f, 1, {1e-12, 1e-12}), Catch::Contains("in float"));
  CHECK(in_float.advance_to(f, 1, {1e-7, 1e-7}).accepted > 0);  // under float's ulp, yet estimates can meet it
  CHECK_THROWS_WITH(s.advance_to(b, std::nan(""), {}), Catch::Contains("t_end"));
  s.advance_to(b, 1, {});
  CHECK_THROWS_WITH(s.advance_to(b, 0.5, {}), Catch::Contains("not before time()"));
  CHECK(s.advance_to(b, 1, {}).accepted == 0);  // already there
}

TEST_CASE("a tiny atol on a component at zero sizes the first step as larger ones do", "[adaptive]") {
  // The orbit's z components are 0: weights 1 / atol past 1e154 once squared to inf, and the
  // first step came out 0 ("the step size underflows at t = 0").
  const auto run = [](double atol) {
    ParticleSet<double> b = at_periapsis();
    Stepper<double> s(attractor(), dopri5, test::serial_options());
    const AdaptiveStats stats = s.advance_to(b, kPeriod, {1e-8, atol});
    CHECK(s.time() == kPeriod);
    return std::pair{stats.accepted, error_after_one_period(b)};
  };
  const auto [steps, error] = run(1e-30);
  for (const double atol : {1e-160, 1e-300, 4.9e-324}) {
    const auto [tiny_steps, tiny_error] = run(atol);  // (155 steps against 175 here)
    CHECK(double(tiny_steps) == Approx(double(steps)).epsilon(0.2));
    CHECK(tiny_error == Approx(error).epsilon(0.05));
  }
}

TEST_CASE("a stopped call whose set changed before it goes on starts afresh", "[adaptive]") {
  // A spring to the origin: x(t) = x0 cos(t - t0) + v0 sin(t - t0). The stopped call keeps
  // stage 0's accelerations; a body moved (or pushed) in between must not take them.
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, 1, 0});
  const Tolerances tol{1e-6, 1e-6};
  const auto always = [] { return true; };  // a stop after every accepted step
  const auto stopped_thrice = [&](Stepper<double>& s) {
    ParticleSet<double> b;
    b.add({1, 0, 0}, {0, 0, 0}, 1);
    for (int k = 0; k < 3; ++k) REQUIRE(s.advance_to(b, 10, tol, always).stopped);
    return b;
  };
  const std::vector<std::function<void(ParticleSet<double>&)>> edits{
      [](ParticleSet<double>& b) { b.set_position(0, {-3, 0, 0}); },
      [](ParticleSet<double>& b) { b.vy()[0] = 2; },  // through the arrays
      [](ParticleSet<double>& b) { b.apply_force(0, {0, 0, 1}); },
      [](ParticleSet<double>& b) { b.set_mass(0, 2); },
      [](ParticleSet<double>& b) { b.set_linear_damping(0, 0.5); }};
  for (const auto& edit : edits) {
    Stepper<double> resumed(f, dopri5, test::serial_options()), other(f, dopri5, test::serial_options());
    ParticleSet<double> a = stopped_thrice(resumed), b = stopped_thrice(other);
    edit(a), edit(b);
    Stepper<double> fresh(f, dopri5, test::serial_options());  // the same clock and set, nothing kept
    fresh.set_time(resumed.time());
    resumed.advance_to(a, 10, tol, always);
    fresh.advance_to(b, 10, tol, always);
    CHECK(resumed.time() == fresh.time());
    CHECK(test::state_hash(a) == test::state_hash(b));
  }
  // Unchanged, it goes on: the step after a stop is the one the straight call takes.
  Stepper<double> straight(f, dopri5, test::serial_options()), stopping(f, dopri5, test::serial_options());
  ParticleSet<double> a = stopped_thrice(stopping), b;
  b.add({1, 0, 0}, {0, 0, 0}, 1);
  for (int k = 0; k < 4; ++k) stopping.advance_to(a, 10, tol, always);
  straight.advance_to(b, 10, tol, [&, k = 0]() mutable { return ++k == 7; });
  CHECK(stopping.time() == straight.time());
  CHECK(test::state_hash(a) == test::state_hash(b));
}

TEST_CASE("limit_to_stable_step keeps the driver's steps within the method's stability limit", "[adaptive][stability]") {
  // Heavy drag (rate 1000) on a slow spring (omega 1): once the drag's transient has decayed,
  // accuracy alone would allow long steps, which the drag's eigenvalue makes unstable; the
  // uncapped controller keeps probing past the limit.
  ForceModel<double> f;
  f.add(LinearDrag{1000});
  f.add(Spring{{0, 0, 0}, 1, 0});
  const auto largest = [&](bool capped) {
    ParticleSet<double> b;
    b.add({1, 0, 0}, {1, 0, 0}, 1);
    Stepper<double> s(f, dopri5, test::serial_options());
    Tolerances t{1e-4, 1e-4};
    t.limit_to_stable_step = capped;
    return s.advance_to(b, 20, t).largest_step;
  };
  ParticleSet<double> start;
  start.add({1, 0, 0}, {1, 0, 0}, 1);
  const double stable = largest_stable_step(dopri5, estimate_stiffness(start, f));
  CHECK(stable == Approx(3.3066 / 1000).epsilon(0.01));
  // The driver's own estimate (fewer iterations) agrees to well within 0.1%.
  CHECK(largest(true) <= stable * 1.001);
  CHECK(largest(false) > stable * 1.01);
}

TEST_CASE("the error norm's sums give a plain loop's bits in the clone this CPU runs", "[adaptive][determinism]") {
  // The same operations in the same order as kernels/reductions.cpp: the stage sum in double, the
  // terms into 16 running sums, added in order.
  const auto reference = []<class T>(const std::vector<T>& y0, const std::vector<T>& y1,
                                     const std::vector<std::vector<T>>& k, const std::vector<double>& w) {
    double sums[16] = {};
    for (std::size_t i = 0; i < y0.size(); ++i) {
      double e = w[0] * double(k[0][i]);
      for (std::size_t s = 1; s < k.size(); ++s) e += w[s] * double(k[s][i]);
      const double scale = 1e-6 + 1e-5 * std::max(std::abs(double(y0[i])), std::abs(double(y1[i])));
      const double q = e == 0 ? 0.0 : e / scale;
      sums[i % 16] += q * q;
    }
    double total = 0;
    for (double x : sums) total += x;
    return total;
  };
  const auto check = [&]<class T>() {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(-3, 3);
    const std::size_t n = 1000;  // not a multiple of 16: the tail too
    std::vector<T> y0(n), y1(n);
    std::vector<std::vector<T>> k(7, std::vector<T>(n));
    for (std::size_t i = 0; i < n; ++i) {
      y0[i] = T(u(rng)), y1[i] = T(u(rng));
      for (auto& ks : k) ks[i] = T(u(rng));
    }
    y1[17] = 0, y0[17] = 0;  // a zero term
    const std::vector<double> w = {0.1, -0.2, 0.3, 0.05, -0.07, 0.011, 0.025};
    const T* kp[7];
    for (int s = 0; s < 7; ++s) kp[s] = k[std::size_t(s)].data();
    const double got = error_squares(y0.data(), y1.data(), kp, w.data(), 7, 1e-5, 1e-6, n);
    CHECK(std::bit_cast<std::uint64_t>(got) == std::bit_cast<std::uint64_t>(reference(y0, y1, k, w)));
    y1[3] = std::numeric_limits<T>::infinity();  // an overflowed candidate is never accepted
    CHECK(std::isinf(error_squares(y0.data(), y1.data(), kp, w.data(), 7, 1e-5, 1e-6, n)));
  };
  check.template operator()<float>();
  check.template operator()<double>();
}

TEST_CASE("a callback that throws inside an attempt leaves the bodies at the last accepted step", "[adaptive]") {
  // On two threads with springs (stages are jobs of their own): a torn state would advance
  // some blocks twice over the same time, an error far above the tolerance.
  const std::size_t n = 5000;
  ForceModel<double> f = test::all_local_terms<double>();
  Springs chain;
  for (std::uint32_t i = 1; i < std::uint32_t(n); ++i) chain.pairs.push_back({i - 1, i, 0.5, 20, 0.1});
  f.add(chain);
  bool thrown = false;
  ForceModel<double> throwing = f;
  throwing.add([&thrown](const ParticleBlock<double>& block) {
    if (block.t > 0.25 && block.begin == 2048 && !thrown) {
      thrown = true;
      throw std::runtime_error("callback failed");
    }
  });
  TbbJobSystem jobs(2);
  StepperOptions o;
  o.jobs = &jobs;
  o.workers = WorkerChoice::all;
  const Tolerances tol{1e-9, 1e-9};
  ParticleSet<double> interrupted = test::cloud<double>(n);
  Stepper<double> s(throwing, dopri5, o);
  CHECK_THROWS_WITH(s.advance_to(interrupted, 0.5, tol), "callback failed");
  CHECK(s.time() < 0.5);
  CHECK(all_finite(interrupted));
  s.advance_to(interrupted, 0.5, tol);  // goes on from the last accepted step
  ParticleSet<double> straight = test::cloud<double>(n);
  Stepper<double>(throwing, dopri5, o).advance_to(straight, 0.5, tol);
  double worst = 0;
  for (std::size_t i = 0; i < n; ++i) worst = std::max(worst, test::distance(interrupted.position(i), straight.position(i)));
  CHECK(worst < 1e-6);
}
