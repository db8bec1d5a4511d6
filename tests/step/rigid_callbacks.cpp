// Rigid bodies under forces and torques from user code (RigidCallback), on every method.
#include <catch2/catch.hpp>

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <stdexcept>
#include <string>

#include "support.hpp"

using namespace kinema;

namespace {

// A restoring torque toward upright: tau = -k 2 (qx, qy, qz) (sign of qw), -k theta for
// small angles theta about any axis.
template <class T>
RigidCallback<T> upright_torque(double k) {
  return [k](const RigidBlock<T>& b) {
    for (std::size_t i = 0; i < b.count; ++i) {
      const T s = b.qw[i] < 0 ? T(-2 * k) : T(2 * k);
      b.tx[i] -= s * b.qx[i];
      b.ty[i] -= s * b.qy[i];
      b.tz[i] -= s * b.qz[i];
    }
  };
}

// The period of the body's turn about z, from its upward zero crossings of qz (linearly
// interpolated) over `periods` periods.
double measured_period(const Method& method, double k, double iz, double h, int periods) {
  RigidBodySet<double> b;
  const double theta0 = 1e-3;
  b.add({{}, {}, {std::cos(theta0 / 2), 0, 0, std::sin(theta0 / 2)}, {}, 1, {1, 2, iz}});
  ForceModel<double> f;
  f.add(upright_torque<double>(k));
  Stepper<double> s(f, method, test::serial_options());
  const double expected = 2 * std::numbers::pi * std::sqrt(iz / k);
  double first = -1, last = -1, previous = b.orientation(0)[3];
  int crossings = 0;
  while (s.time() < (periods + 0.5) * expected) {
    s.step(b, h);
    const double now = b.orientation(0)[3];
    if (previous < 0 && now >= 0) {
      const double at = s.time() - h * now / (now - previous);
      if (crossings++ == 0) first = at;
      last = at;
    }
    previous = now;
  }
  return (last - first) / (crossings - 1);
}

template <class T>
RigidBodySet<T> tumbling(std::size_t n) {
  RigidBodySet<T> set;
  for (std::size_t i = 0; i < n; ++i) {
    const T a = T(i % 17) / 17, c = T(i % 5) / 5;
    set.add({{T(i % 10), a, c}, {c, T(-1), a}, {1, a, c, T(0.3)}, {a, T(1), c}, T(1) + a, {T(1) + a, T(2), T(2.5) - c}});
  }
  return set;
}

// A callback with a force and a torque that depend on the whole view.
template <class T>
ForceModel<T> callback_model(double throw_at = -1, std::size_t throw_block = 0) {
  ForceModel<T> f = test::all_local_terms<T>(true, false);
  f.add(AngularDrag{0.05});
  f.add([=](const RigidBlock<T>& b) {
    if (b.begin == throw_block && b.t == throw_at) throw std::runtime_error("rigid callback failed");
    for (std::size_t i = 0; i < b.count; ++i) {
      b.fx[i] += T(0.5) * b.qx[i] - b.wy[i] * b.lz[i];
      b.fy[i] += b.vz[i] * b.inv_mass[i];
      b.tz[i] += T(0.1) * b.px[i] * b.inv_iz[i] - T(0.2) * b.wz[i];
      b.tx[i] += T(std::sin(b.t)) * b.qy[i];
    }
  });
  return f;
}

}  // namespace

TEST_CASE("a callback torque toward upright oscillates at sqrt(k / I)", "[rigid][callbacks]") {
  const double k = 2, iz = 0.5;
  const double expected = 2 * std::numbers::pi * std::sqrt(iz / k);
  for (const Method* m : {&rk4, &velocity_verlet, &dopri5, &midpoint}) {
    INFO(m->name);
    const double period = measured_period(*m, k, iz, 1e-3, 10);
    CHECK(std::abs(period / expected - 1) < 1e-6);
  }
  // Too soft a spring shows: the frequency is that of I, not of another moment.
  CHECK(std::abs(measured_period(rk4, 2 * k, iz, 1e-3, 4) / expected - 1) > 0.2);
}

TEST_CASE("a callback force at the centre moves it as a built-in term does", "[rigid][callbacks]") {
  // The same spring as a built-in term (fused path) and as a callback (block path), rk4.
  RigidBodySet<double> a = tumbling<double>(300), b = a;
  ForceModel<double> built_in;
  built_in.add(Spring{{0, 0, 0}, 3, 0});
  ForceModel<double> by_callback;
  by_callback.add([](const RigidBlock<double>& v) {
    for (std::size_t i = 0; i < v.count; ++i) {
      v.fx[i] -= 3 * v.px[i], v.fy[i] -= 3 * v.py[i], v.fz[i] -= 3 * v.pz[i];
    }
  });
  Stepper<double> fused(built_in, rk4, test::serial_options()), block(by_callback, rk4, test::serial_options());
  fused.advance(a, 0.01, 100);
  block.advance(b, 0.01, 100);
  CHECK(fused.scratch_bytes() == 0);  // the fused kernel: no stage state in memory
  CHECK(block.scratch_bytes() > 0);   // the block path's
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(test::distance(a.centers().position(i), b.centers().position(i)) < 1e-12);
    for (int c = 0; c < 4; ++c) CHECK(a.orientation(i)[c] == Approx(b.orientation(i)[c]).margin(1e-12));
  }
}

TEST_CASE("rigid callbacks: the same bits on every ISA, thread count and job system", "[rigid][callbacks][determinism]") {
  for (const Method* m : {&rk4, &velocity_verlet, &bs3}) {
    INFO(m->name);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t n) {
          RigidBodySet<float> b = tumbling<float>(n);
          for (std::size_t i = 0; i < n; i += 5) b.apply_force_at(i, {1, 0, 2}, {0, 1, 0});
          Stepper<float> s(callback_model<float>(), *m, o);
          s.advance(b, 0.01f, 8);
          REQUIRE(all_finite(b));
          return test::state_hash(b);
        },
        1500, 5000);
  }
}

// The rigid block path's results as recorded (2026-12-05): every method that path runs, fixed
// steps and advance_to. A rework of its kernels must keep them. (advance_to's moved on
// 2026-12-06, the kernels' bits kept: its first step is now the documented estimate
// 0.01 |y| / |f(y)|, as the particles', where it was 0.01 (t_end - t).)
TEST_CASE("the rigid block path keeps its recorded bits", "[rigid][callbacks][determinism]") {
  const std::map<std::string, std::uint64_t> recorded = {
      {"euler", 0x403b3ff9d49029c9ull},
      {"midpoint", 0xd9a86a460446d2fdull},
      {"heun", 0x54dcfc4fb7101a11ull},
      {"rk4", 0x28480354965e815cull},
      {"bs3", 0x29671312295fc7a5ull},
      {"rk6", 0x8246ad13869cbdf7ull},
      {"dopri5", 0x314c78f70695a399ull},
      {"symplectic_euler", 0xb3c6b859aff986f7ull},
      {"velocity_verlet", 0xab3d7f00c1dcd56aull},
      {"advance_to", 0x32f68f6b2dc05eb4ull},
      {"double rk4", 0x23820755d493b365ull}};
  const auto check = [&](const std::string& name, std::uint64_t hash) {
    INFO(name);
    if (recorded.at(name) != hash) std::printf("      {\"%s\", 0x%016" PRIx64 "ull},\n", name.c_str(), hash);
    CHECK(recorded.at(name) == hash);
  };
  for (const Method* m : {&euler, &midpoint, &heun, &rk4, &bs3, &rk6, &dopri5, &symplectic_euler, &velocity_verlet}) {
    RigidBodySet<float> b = tumbling<float>(700);
    Stepper<float> s(callback_model<float>(), *m, test::serial_options());
    s.advance(b, 0.01f, 6);
    check(std::string(m->name), test::state_hash(b));
  }
  RigidBodySet<float> b = tumbling<float>(700);
  Stepper<float> s(callback_model<float>(), dopri5, test::serial_options());
  s.advance_to(b, 0.2, {1e-5, 1e-5});
  check("advance_to", test::state_hash(b));
  RigidBodySet<double> d = tumbling<double>(700);
  Stepper<double> sd(callback_model<double>(), rk4, test::serial_options());
  sd.advance(d, 0.01, 6);
  check("double rk4", test::state_hash(d));
}

TEST_CASE("advance(n) on the rigid block path gives the bits of n steps", "[rigid][callbacks][determinism]") {
  RigidBodySet<double> a = tumbling<double>(3000), b = a;
  Stepper<double> sa(callback_model<double>(), rk4, test::serial_options());
  Stepper<double> sb(callback_model<double>(), rk4, test::serial_options());
  sa.advance(a, 0.01, 12);
  for (int k = 0; k < 12; ++k) sb.step(b, 0.01);
  CHECK(test::state_hash(a) == test::state_hash(b));
}

TEST_CASE("a rigid callback that throws leaves the set as before the step that threw", "[rigid][callbacks][embedding]") {
  TbbJobSystem tbb(2);
  StepperOptions threaded;
  threaded.jobs = &tbb;
  threaded.workers = WorkerChoice::all;
  for (StepperOptions o : {test::serial_options(), threaded}) {
    const double h = 0.01, when = 4 * h + 0.5 * h;  // rk4's second stage of the fifth step
    RigidBodySet<double> expected = tumbling<double>(3000);
    Stepper<double>(callback_model<double>(), rk4, o).advance(expected, h, 4);
    RigidBodySet<double> b = tumbling<double>(3000);
    Stepper<double> s(callback_model<double>(when, 1024), rk4, o);
    CHECK_THROWS_WITH(s.advance(b, h, 9), "rigid callback failed");
    CHECK(test::state_hash(b) == test::state_hash(expected));
    CHECK(s.time() == Approx(4 * h).epsilon(1e-15));
  }
}

TEST_CASE("particles ignore rigid callbacks, rigid bodies particle callbacks", "[rigid][callbacks]") {
  ForceModel<float> f = test::all_local_terms<float>();
  f.add([](const RigidBlock<float>&) { throw std::runtime_error("rigid callback called"); });
  Stepper<float> s(f, rk4, test::serial_options());
  CHECK(s.fused());
  ParticleSet<float> p = test::cloud<float>(100);
  s.step(p, 0.01f);
  ForceModel<float> g = test::all_local_terms<float>();
  g.add([](const ParticleBlock<float>&) { throw std::runtime_error("particle callback called"); });
  RigidBodySet<float> r = tumbling<float>(100), fused = r;
  Stepper<float>(g, rk4, test::serial_options()).step(r, 0.01f);
  Stepper<float>(test::all_local_terms<float>(), rk4, test::serial_options()).step(fused, 0.01f);
  CHECK(test::state_hash(r) == test::state_hash(fused));
  CHECK_THROWS_WITH(f.add(RigidCallback<float>{}), Catch::Contains("empty"));
}
