// Per-body parameters: gravity factors, linear and angular damping rates.
#include <catch2/catch.hpp>

#include <cmath>
#include <type_traits>

#include "kinema/checkpoint.hpp"
#include "support.hpp"

using namespace kinema;

namespace {

const Vec3<double> kG{0.5, -9.81, 0.25};

// The three particle paths: fused, staged, and the block path (a callback that adds nothing).
enum class Path { fused, staged, block };

Stepper<double> stepper_on(Path path, ForceModel<double> f, const Method& m) {
  StepperOptions o = test::serial_options();
  o.force_staged = path == Path::staged;
  if (path == Path::block) f.add([](const ParticleBlock<double>&) {});
  return Stepper<double>(std::move(f), m, o);
}

// Parameters that differ from body to body, so that a mix-up of bodies shows.
template <class Set>
void set_parameters(Set& b) {
  using T = std::decay_t<decltype(b.gravity_factor(0))>;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (i % 3 != 1) b.set_gravity_factor(i, T(0.25 * double(i % 5) - 0.5));
    if (i % 2 == 0) b.set_linear_damping(i, T(0.1 * double(i % 7)));
  }
}

}  // namespace

TEST_CASE("a gravity factor scales gravity: x0 + v0 t + f g t^2 / 2 under rk4", "[forces][parameters]") {
  const Vec3<double> x0{1, 2, -3}, v0{0.5, 3, 1};
  const double h = 0.01;
  const int n = 100;
  ForceModel<double> f;
  f.add(Gravity{kG});
  for (Path path : {Path::fused, Path::staged, Path::block}) {
    for (double factor : {0.0, 0.35, -1.0, 2.0}) {
      INFO("path " << int(path) << " factor " << factor);
      ParticleSet<double> b;
      b.add(x0, v0, 3);
      b.add(x0, v0, 3);  // keeps the default, 1
      b.set_gravity_factor(0, factor);
      stepper_on(path, f, rk4).advance(b, h, n);
      const double t = n * h;
      for (int d = 0; d < 3; ++d) {
        CHECK(b.position(0)[d] == Approx(x0[d] + v0[d] * t + factor * kG[d] * t * t / 2).margin(1e-12));
        CHECK(b.velocity(0)[d] == Approx(v0[d] + factor * kG[d] * t).margin(1e-12));
        CHECK(b.velocity(1)[d] == Approx(v0[d] + kG[d] * t).margin(1e-12));
      }
    }
  }
}

TEST_CASE("linear damping c decays velocity as exp(-c t), whatever the mass", "[forces][parameters]") {
  const Vec3<double> x0{0, 1, 2}, v0{3, -2, 1};
  const double c = 1.5, drag = 0.6, h = 1e-3;
  const int n = 2000;
  ForceModel<double> f;
  f.add(LinearDrag{drag});
  for (Path path : {Path::fused, Path::staged, Path::block}) {
    for (const Method* m : {&rk4, &heun}) {  // kick-drift methods are first order with damping
      INFO("path " << int(path) << " " << m->name);
      ParticleSet<double> b;
      b.add(x0, v0, 2);
      b.add(x0, v0, 8);
      b.set_linear_damping(0, c);
      b.set_linear_damping(1, c);
      stepper_on(path, f, *m).advance(b, h, n);
      const double t = n * h;
      const double tol = m == &rk4 ? 1e-11 : 1e-5;  // fourth order, second
      for (std::size_t i : {0u, 1u}) {
        const double rate = c + drag / (i == 0 ? 2 : 8);  // the drag force's share depends on mass
        for (int d = 0; d < 3; ++d) {
          CHECK(b.velocity(i)[d] == Approx(v0[d] * std::exp(-rate * t)).margin(tol));
          CHECK(b.position(i)[d] == Approx(x0[d] + v0[d] * (1 - std::exp(-rate * t)) / rate).margin(tol));
        }
      }
    }
  }
}

TEST_CASE("angular damping c decays a sphere's angular momentum as exp(-c t)", "[rigid][parameters]") {
  const Vec3<double> l0{0.3, -1.2, 2};
  const double c = 0.8, h = 1e-3;
  const int n = 1500;
  for (const Method* m : {&rk4, &midpoint, &dopri5}) {
    for (bool block : {false, true}) {
      INFO(m->name << " block path " << block);
      RigidBodySet<double> b;
      b.add({{1, 2, 3}, {1, 0, 0}, {1, 0, 0, 0}, l0, 2, {0.5, 0.5, 0.5}});
      b.set_angular_damping(0, c);
      b.set_linear_damping(0, c);
      ForceModel<double> f;
      if (block) f.add([](const RigidBlock<double>&) {});
      Stepper<double> s(f, *m, test::serial_options());
      s.advance(b, h, n);
      const double t = n * h, tol = m == &midpoint ? 1e-5 : 1e-11;
      for (int d = 0; d < 3; ++d) CHECK(b.angular_momentum(0)[d] == Approx(l0[d] * std::exp(-c * t)).margin(tol));
      CHECK(b.centers().velocity(0)[0] == Approx(std::exp(-c * t)).margin(tol));
    }
  }
}

TEST_CASE("kinematic bodies ignore gravity factors and damping", "[forces][parameters]") {
  ForceModel<double> f;
  f.add(Gravity{kG});
  ParticleSet<double> b;
  b.add_kinematic({1, 2, 3}, {1, 0, 0});
  b.set_gravity_factor(0, 3);
  b.set_linear_damping(0, 5);
  Stepper<double>(f, rk4, test::serial_options()).advance(b, 0.01, 100);
  CHECK(b.velocity(0) == Vec3<double>{1, 0, 0});
  CHECK(b.position(0)[0] == Approx(2));

  RigidBodySet<double> r;
  r.add({{0, 0, 0}, {}, {1, 0, 0, 0}, {1, 2, 3}, 1, {1, 1, 1}});
  r.set_kinematic(0);
  r.set_angular_damping(0, 4);
  Stepper<double>(ForceModel<double>{}, rk4, test::serial_options()).advance(r, 0.01, 50);
  CHECK(r.angular_momentum(0) == Vec3<double>{1, 2, 3});
}

TEST_CASE("a set carries parameter arrays only once one is set, and keeps them with its bodies",
          "[bodies][parameters]") {
  ParticleSet<float> b = test::cloud<float>(100);
  CHECK_FALSE(b.parameters().any());
  CHECK(b.parameters().data(BodyParameter::gravity_factor) == nullptr);
  CHECK(b.gravity_factor(7) == 1.0f);
  CHECK(b.linear_damping(7) == 0.0f);
  b.set_gravity_factor(7, 0.5f);
  CHECK(b.parameters().data(BodyParameter::gravity_factor) != nullptr);
  CHECK(b.parameters().data(BodyParameter::linear_damping) == nullptr);  // only the kinds set
  b.set_linear_damping(99, 2.0f);
  for (int k = 0; k < 500; ++k) b.add({0, 0, 0}, {0, 0, 0}, 1);  // grows: new bodies get the defaults
  CHECK(b.gravity_factor(7) == 0.5f);
  CHECK(b.gravity_factor(400) == 1.0f);
  CHECK(b.linear_damping(400) == 0.0f);
  b.remove(7);  // the last body moves into 7
  CHECK(b.gravity_factor(7) == 1.0f);
  ParticleSet<float> copy = b;
  CHECK(copy.linear_damping(99) == 2.0f);
  b.clear();
  CHECK_FALSE(b.parameters().any());

  CHECK_THROWS_WITH(copy.set_gravity_factor(0, NAN), Catch::Contains("gravity factor must be finite"));
  CHECK_THROWS_WITH(copy.set_linear_damping(0, -1.0f), Catch::Contains("linear damping"));
  CHECK_THROWS_WITH(copy.set_linear_damping(100000, 1.0f), Catch::Contains("no such body"));
  RigidBodySet<double> r;
  r.add({});
  CHECK_THROWS_WITH(r.set_angular_damping(0, INFINITY), Catch::Contains("angular damping"));
  CHECK(r.angular_damping(0) == 0);
  // Reading past the set, with the arrays there or not: refused (it read past them).
  CHECK_THROWS_WITH(copy.gravity_factor(copy.size()), Catch::Contains("no such body"));
  CHECK_THROWS_WITH(copy.linear_damping(100000), Catch::Contains("no such body"));
  r.set_angular_damping(0, 0.5);
  CHECK_THROWS_WITH(r.angular_damping(1), Catch::Contains("no such body"));
  CHECK_THROWS_WITH(r.gravity_factor(1), Catch::Contains("no such body"));
}

TEST_CASE("the fused, staged and block paths give parameters the same bits", "[determinism][parameters]") {
  for (const Method* m : builtin_methods) {
    INFO(m->name);
    auto run = [&](bool staged) {
      ParticleSet<float> b = test::cloud<float>(3000);
      set_parameters(b);
      StepperOptions o = test::serial_options();
      o.force_staged = staged;
      Stepper<float> s(test::all_local_terms<float>(true, true), *m, o);
      s.advance(b, 0.01f, 5);
      return test::state_hash(b);
    };
    CHECK(run(false) == run(true));
  }
}

TEST_CASE("parameters: the same bits on every ISA, thread count and job system", "[determinism][parameters]") {
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t n) {
          ParticleSet<float> b = test::cloud<float>(n);
          set_parameters(b);
          Stepper<float> s(test::all_local_terms<float>(false, false), *m, o);
          s.advance(b, 0.01f, 10);
          return test::state_hash(b);
        },
        2000, 9000);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t n) {
          RigidBodySet<float> b;
          for (std::size_t i = 0; i < n; ++i) {
            const float a = float(i) * 1e-3f;
            b.add({{a, -a, 1}, {0, a, 0}, {1, a, 0, 0}, {a, 1, -a}, 1 + a, {0.5f, 1 + a, 2}});
            b.set_angular_damping(i, 0.1f * float(i % 4));
          }
          set_parameters(b);
          Stepper<float> s(test::rotational_terms<float>(), *m, o);
          s.advance(b, 0.01f, 10);
          return test::state_hash(b);
        },
        2000, 9000);
  }
}

TEST_CASE("a gravity factor scales the body's gravitational potential energy", "[diagnostics][parameters]") {
  ForceModel<double> f;
  f.add(Gravity{{0, -10, 0}});
  ParticleSet<double> b;
  b.add({0, 3, 0}, {}, 2);
  const double plain = potential_energy(b, f);
  b.set_gravity_factor(0, 0.25);
  CHECK(potential_energy(b, f) == Approx(0.25 * plain));
  CHECK(plain == Approx(60));
}

TEST_CASE("a checkpoint keeps the parameters: the resumed run gives the bits of the straight one",
          "[checkpoint][parameters]") {
  ForceModel<float> f = test::all_local_terms<float>(false, false);
  auto make = [] {
    RigidBodySet<float> b;
    for (int i = 0; i < 40; ++i) b.add({{float(i), 0, 0}, {0, 1, 0}, {1, 0, 0, 0}, {1, float(i), 0}, 1, {1, 2, 3}});
    set_parameters(b);
    for (std::size_t i = 0; i < b.size(); i += 3) b.set_angular_damping(i, 0.5f);
    return b;
  };
  RigidBodySet<float> straight = make(), first = make();
  Stepper<float> a(f, rk4, test::serial_options()), s(f, rk4, test::serial_options());
  a.advance(straight, 0.01f, 20);
  s.advance(first, 0.01f, 10);
  CheckpointWriter out;
  out.add(first, s);
  RigidBodySet<float> resumed;
  Stepper<float> r(f, rk4, test::serial_options());
  CheckpointReader(out.bytes()).restore(0, resumed, r);
  CHECK(resumed.angular_damping(3) == 0.5f);
  CHECK(resumed.gravity_factor(2) == first.gravity_factor(2));
  r.advance(resumed, 0.01f, 10);
  CHECK(test::state_hash(resumed) == test::state_hash(straight));
}

TEST_CASE("parameters of an empty set survive a checkpoint; a particle record leaves out angular damping",
          "[checkpoint][parameters]") {
  Stepper<float> s(ForceModel<float>{}, rk4, test::serial_options());
  ParticleSet<float> emptied;
  emptied.add({0, 0, 0}, {}, 1);
  emptied.set_gravity_factor(0, 2);
  emptied.apply_force(0, {1, 0, 0});
  emptied.remove(0);
  CheckpointWriter out;
  out.add(emptied, s);
  ParticleSet<float> back;
  CheckpointReader(out.bytes()).restore(0, back, s);
  for (int k = 0; k < 40; ++k) back.add({0, 0, 0}, {}, 1);  // grows arrays that exist
  CHECK(back.gravity_factor(39) == 1.0f);
  CHECK(back.applied_force(39) == Vec3<float>{});

  RigidBodySet<float> r;
  r.add({});
  r.set_angular_damping(0, 0.5f);
  ParticleSet<float> centers = r.centers();  // carries the angular damping array
  CheckpointWriter particles;
  particles.add(centers, s);
  ParticleSet<float> restored;
  CheckpointReader(particles.bytes()).restore(0, restored, s);
  CHECK(restored.size() == 1);
}

TEST_CASE("a gravity factor or damping rate that overflows with the step is refused before the step",
          "[errors][parameters]") {
  ForceModel<float> f;
  f.add(Gravity{{0, -10, 0}});
  ParticleSet<float> b;
  b.add({0, 0, 0}, {}, 1);
  b.set_gravity_factor(0, 3e38f);  // finite; times g = 10 it is not
  Stepper<float> s(f, rk4, test::serial_options());
  CHECK_THROWS_WITH(s.step(b, 1.0f), Catch::Contains("gravity factors or damping rates overflows"));
  CHECK(b.position(0) == Vec3<float>{});
  CHECK(s.time() == 0);
  RigidBodySet<float> r;
  r.add({});
  r.set_angular_damping(0, 3e38f);
  CHECK_THROWS_WITH(s.step(r, 10.0f), Catch::Contains("overflows"));
}
