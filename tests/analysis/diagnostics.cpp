// Energies, momentum and the finiteness check against hand-computed values.
#include <catch2/catch.hpp>

#include <cmath>

#include "support.hpp"

using namespace kinema;

TEST_CASE("energies and momentum match hand computation", "[diagnostics]") {
  ParticleSet<double> b;
  b.add({1, 2, 0}, {3, 0, 4}, 2);    // speed 5
  b.add({0, -1, 0}, {0, 1, 0}, 0.5);
  b.add_kinematic({9, 9, 9}, {100, 0, 0});  // no mass: left out
  ForceModel<double> f;
  f.add(Gravity{{0, -10, 0}}).add(Spring{{1, 0, 0}, 4, 1}).add(Central{{0, 0, 0}, 3});
  f.add(LinearDrag{7});  // dissipative: no potential
  CHECK(kinetic_energy(b) == Approx(0.5 * 2 * 25 + 0.5 * 0.5 * 1));
  const double gravity = 2 * 10 * 2 + 0.5 * 10 * -1;          // -m g.x
  const double spring = 0.5 * 4 * (0 + 4) + 0.5 * 4 * (1 + 1);  // k |x - a|^2 / 2
  const double central = -3 * 2 / std::sqrt(5.0) - 3 * 0.5 / 1;
  CHECK(potential_energy(b, f) == Approx(gravity + spring + central));
  CHECK(energy(b, f).total() == Approx(kinetic_energy(b) + potential_energy(b, f)));
  const auto p = momentum(b);
  CHECK(p[0] == Approx(6));
  CHECK(p[1] == Approx(0.5));
  CHECK(p[2] == Approx(8));
}

TEST_CASE("the finiteness check catches a blown-up state", "[diagnostics]") {
  ParticleSet<float> b;
  b.add({0, 0, 0}, {0, 0, 0}, 1);  // sitting on the attractor: 0/0
  ForceModel<float> f;
  f.add(Central{{0, 0, 0}, 1});
  CHECK(all_finite(b));
  Stepper<float> s(f, euler, test::serial_options());
  s.step(b, 0.1f);
  CHECK_FALSE(all_finite(b));
}

TEST_CASE("undamped motion conserves energy to the method's accuracy", "[diagnostics]") {
  ParticleSet<double> b = test::cloud<double>(100);
  ForceModel<double> f;
  f.add(Gravity{{0, -9.81, 0}}).add(Spring{{0, 0, 0}, 4, 0});
  const double e0 = energy(b, f).total();
  Stepper<double> s(f, rk4, test::serial_options());
  s.advance(b, 0.001, 1000);
  CHECK(energy(b, f).total() == Approx(e0).epsilon(1e-10));
}

TEST_CASE("rigid-body energy and angular momentum match hand computation", "[diagnostics][rigid]") {
  RigidBodySet<double> b;
  // Spin 2 about body z (I_z = 4): L = 8, rotational energy = 1/2 I w^2 = 8.
  b.add({{1, 0, 0}, {0, 3, 0}, {1, 0, 0, 0}, {0, 0, 8}, 2, {1, 2, 4}});
  ForceModel<double> f;
  f.add(Gravity{{0, -10, 0}});
  CHECK(rotational_energy(b) == Approx(8));
  CHECK(energy(b, f).kinetic == Approx(8 + 0.5 * 2 * 9));
  CHECK(energy(b, f).potential == Approx(0));
  const auto l = angular_momentum(b);  // spin 8 plus m x cross v = 2 * (1,0,0) x (0,3,0) = (0,0,6)
  CHECK(l[2] == Approx(14));
  CHECK(all_finite(b));
}
