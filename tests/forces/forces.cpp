// Callback and coupled terms: the staged path runs them at the right stage times, in
// parallel, with the same bits for any thread count.
#include <catch2/catch.hpp>

#include <cmath>

#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

// Springs of stiffness k between consecutive bodies of a chain.
class ChainSprings final : public CoupledTerm<double> {
 public:
  ChainSprings(std::size_t count, double k) : count_(count), k_(k) {}

  void accumulate(const ParticleState<double>& all, const ParticleBlock<double>& b) const override {
    const double* x[3] = {all.px, all.py, all.pz};
    double* f[3] = {b.fx, b.fy, b.fz};
    for (std::size_t n = 0; n < b.count; ++n) {
      const std::size_t i = b.begin + n;
      if (i >= count_) break;
      for (int d = 0; d < 3; ++d) {
        if (i > 0) f[d][n] -= k_ * (x[d][i] - x[d][i - 1]);
        if (i + 1 < count_) f[d][n] -= k_ * (x[d][i] - x[d][i + 1]);
      }
    }
  }

  double potential_energy(const ParticleState<double>& all) const override {
    double u = 0;
    for (std::size_t i = 1; i < count_; ++i) {
      const double dx = all.px[i] - all.px[i - 1], dy = all.py[i] - all.py[i - 1],
                   dz = all.pz[i] - all.pz[i - 1];
      u += 0.5 * k_ * (dx * dx + dy * dy + dz * dz);
    }
    return u;
  }

 private:
  std::size_t count_;
  double k_;
};

}  // namespace

TEST_CASE("a callback force sees each stage's time", "[forces][callback]") {
  // x'' = sin t from rest: x(t) = t - sin t. Wrong stage times would break rk4's order.
  auto error_at = [](int steps) {
    ForceModel<double> f;
    f.add([](const ParticleBlock<double>& b) {
      // Force m sin t on the one body (mass 2): acceleration sin t.
      for (std::size_t i = 0; i < b.count; ++i) b.fx[i] += 2 * std::sin(b.t);
    });
    const double t = 2;
    const auto s = test::run_one<double>(rk4, f, {0, 0, 0}, {0, 0, 0}, 2, t / steps, steps);
    return std::abs(s.x[0] - (t - std::sin(t)));
  };
  const double e1 = error_at(20), e2 = error_at(40);
  CHECK(e2 < 1e-6);
  CHECK(std::log2(e1 / e2) == Approx(4).margin(0.2));
}

TEST_CASE("a callback spring matches the built-in spring", "[forces][callback]") {
  ForceModel<double> builtin, callback;
  builtin.add(Spring{{0, 0, 0}, 3, 0});
  callback.add([](const ParticleBlock<double>& b) {
    for (std::size_t i = 0; i < b.count; ++i) {
      b.fx[i] -= 3 * b.px[i], b.fy[i] -= 3 * b.py[i], b.fz[i] -= 3 * b.pz[i];
    }
  });
  for (const Method* m : builtin_methods) {
    const auto a = test::run_one<double>(*m, builtin, {1, 2, 0}, {0, 1, 0}, 1.5, 0.01, 500);
    const auto b = test::run_one<double>(*m, callback, {1, 2, 0}, {0, 1, 0}, 1.5, 0.01, 500);
    INFO(m->name);
    CHECK(test::distance(a.x, b.x) < 1e-12);
  }
}

TEST_CASE("two bodies on a coupled spring oscillate at sqrt(2k/m)", "[forces][coupled]") {
  // Relative coordinate of two unit masses: r'' = -2k r. Centre of mass drifts uniformly.
  const double k = 2, t = 3, w = std::sqrt(2 * k);
  ForceModel<double> f;
  f.add(std::make_shared<ChainSprings>(2, k));
  ParticleSet<double> b;
  b.add({-0.5, 0, 0}, {0.25, 0, 0}, 1);
  b.add({0.5, 0, 0}, {0.25, 0, 0}, 1);
  Stepper<double> s(f, rk4, test::serial_options());
  REQUIRE_FALSE(s.fused());
  const double e0 = energy(b, f).total();
  s.advance(b, t / 3000, 3000);
  const double r = b.position(1)[0] - b.position(0)[0];
  CHECK(r == Approx(std::cos(w * t)).margin(1e-10));
  CHECK(momentum(b)[0] == Approx(0.5).margin(1e-13));
  CHECK(energy(b, f).total() == Approx(e0).epsilon(1e-10));
}

TEST_CASE("coupled terms give the same bits on any number of threads", "[forces][coupled]") {
  const std::size_t n = 5000;  // 5 blocks: springs cross block boundaries
  ForceModel<double> f = test::all_local_terms<double>();
  f.add(std::make_shared<ChainSprings>(n, 5.0));
  f.add([](const ParticleBlock<double>& b) {
    for (std::size_t i = 0; i < b.count; ++i) b.fz[i] += std::cos(b.t + b.px[i]);
  });
  auto run = [&](const Method& m, JobSystem& jobs) {
    ParticleSet<double> b = test::cloud<double>(n);
    StepperOptions o;
    o.jobs = &jobs;
    o.workers = WorkerChoice::all;
    Stepper<double> s(f, m, o);
    s.advance(b, 0.005, 10);
    return test::state_hash(b);
  };
  SerialJobSystem serial;
  TbbJobSystem two(2), eight(8);
  test::ThreadPool pool(3);
  for (const Method* m : builtin_methods) {
    const auto h = run(*m, serial);
    INFO(m->name);
    CHECK(run(*m, two) == h);
    CHECK(run(*m, eight) == h);
    CHECK(run(*m, pool) == h);
  }
}

TEST_CASE("forces see t = step * h exactly, never a running sum", "[forces][callback]") {
  std::vector<double> seen;
  ForceModel<double> f;
  f.add([&seen](const ParticleBlock<double>& b) { seen.push_back(b.t); });
  ParticleSet<double> b;
  b.add({0, 0, 0}, {0, 0, 0}, 1);
  Stepper<double> s(f, euler, test::serial_options());
  const double h = 0.1;  // not exact in binary: a running sum would drift from k * h
  s.advance(b, h, 1000);
  REQUIRE(seen.size() == 1000);
  for (std::size_t k = 0; k < seen.size(); ++k) REQUIRE(seen[k] == double(k) * h);
  CHECK(s.time() == 1000 * h);
}
