// Forces from the game: forces, torques and impulses applied to single bodies.
#include <catch2/catch.hpp>

#include <atomic>
#include <cmath>
#include <memory>
#include <vector>

#include "support.hpp"

using namespace kinema;

namespace {

// A force that differs from body to body, so that a mix-up of bodies shows.
template <class T>
Vec3<T> game_force(std::size_t i) {
  return {T(0.5) + T(i % 7), T(-2) * T(i % 3), T(0.25) * T(i % 5)};
}

template <class T>
void apply_game_forces(ParticleSet<T>& b) {
  for (std::size_t i = 0; i < b.size(); i += 3) b.apply_force(i, game_force<T>(i));
}

RigidBodySet<double> sphere_at_rest(double mass, double moment) {
  RigidBodySet<double> b;
  b.add({{1, 2, 3}, {}, {1, 0, 0, 0}, {}, mass, {moment, moment, moment}});
  return b;
}

}  // namespace

TEST_CASE("a constant applied force gives x0 + v0 t + F t^2 / 2m under rk4", "[forces][applied]") {
  const Vec3<double> x0{1, -2, 0.5}, v0{0.3, 2, -1}, F{3, -1.5, 6};
  const double m = 2.5, h = 0.01;
  const int n = 100;
  for (bool staged : {false, true}) {
    INFO("staged " << staged);
    StepperOptions o = test::serial_options();
    o.force_staged = staged;
    ParticleSet<double> b;
    b.add(x0, v0, m);
    b.apply_force(0, F);
    Stepper<double> s(ForceModel<double>{}, rk4, o);
    s.advance(b, h, n);
    const double t = n * h;
    for (int d = 0; d < 3; ++d) {
      CHECK(b.position(0)[d] == Approx(x0[d] + v0[d] * t + F[d] * t * t / (2 * m)).epsilon(1e-13));
      CHECK(b.velocity(0)[d] == Approx(v0[d] + F[d] * t / m).epsilon(1e-13));
    }
    CHECK_FALSE(b.has_applied_forces());  // used by that call, then cleared
  }
}

TEST_CASE("applied forces add to the model's terms and last one call unless kept", "[forces][applied]") {
  ForceModel<double> f;
  f.add(Gravity{{0, -9.81, 0}});
  Stepper<double> s(f, rk4, test::serial_options());
  ParticleSet<double> b;
  b.add({0, 0, 0}, {0, 0, 0}, 2);
  b.apply_force(0, {0, 2 * 9.81, 0});  // holds the body up against gravity
  b.apply_force(0, {1, 0, 0});         // forces on one body add up
  CHECK(b.applied_force(0)[1] == 2 * 9.81);
  s.advance(b, 0.01, 10);
  CHECK(b.velocity(0)[1] == Approx(0).margin(1e-14));
  CHECK(b.velocity(0)[0] == Approx(0.5 * 0.1).epsilon(1e-13));
  s.advance(b, 0.01, 10);  // cleared: gravity alone
  CHECK(b.velocity(0)[1] == Approx(-9.81 * 0.1).epsilon(1e-13));
  CHECK(b.velocity(0)[0] == Approx(0.05).epsilon(1e-13));

  b.keep_forces(true);
  b.apply_force(0, {0, 2 * 9.81, 0});
  const double vy = b.velocity(0)[1];
  for (int k = 0; k < 3; ++k) s.step(b, 0.01);
  CHECK(b.velocity(0)[1] == Approx(vy).margin(1e-14));
  CHECK(b.has_applied_forces());
  b.clear_forces();  // cleared forces stop acting
  s.step(b, 0.01);
  CHECK(b.velocity(0)[1] == Approx(vy - 9.81 * 0.01).epsilon(1e-13));
}

TEST_CASE("an impulse changes momentum by exactly J; kinematic bodies ignore everything", "[forces][applied]") {
  ParticleSet<double> b;
  b.add({0, 0, 0}, {1, 2, 3}, 4);
  b.add_kinematic({5, 0, 0}, {0, 1, 0});
  b.apply_impulse(0, {8, -4, 2});
  CHECK(b.velocity(0) == Vec3<double>{3, 1, 3.5});  // m v changed by J
  b.apply_impulse(1, {8, -4, 2});
  b.apply_force(1, {100, 100, 100});
  CHECK(b.velocity(1) == Vec3<double>{0, 1, 0});
  Stepper<double>(ForceModel<double>{}, rk4, test::serial_options()).advance(b, 0.5, 2);
  CHECK(b.velocity(1) == Vec3<double>{0, 1, 0});
  CHECK(b.position(1) == Vec3<double>{5, 1, 0});
}

TEST_CASE("a set that applies nothing carries no force arrays", "[bodies][applied]") {
  ParticleSet<float> b = test::cloud<float>(100);
  CHECK(b.applied_force_data(0) == nullptr);
  Stepper<float>(test::all_local_terms<float>(), rk4, test::serial_options()).advance(b, 0.01f, 3);
  CHECK(b.applied_force_data(0) == nullptr);
  b.apply_force(5, {1, 2, 3});
  REQUIRE(b.applied_force_data(0) != nullptr);
  for (std::size_t i = 0; i < b.padded_size(); ++i) CHECK(b.applied_force_data(1)[i] == (i == 5 ? 2.0f : 0.0f));
  b.clear_forces();
  CHECK(b.applied_force_data(0) == nullptr);
  b.apply_force(7, {0, 1, 0});  // a new frame starts from zero
  CHECK(b.applied_force(5) == Vec3<float>{0, 0, 0});
  CHECK(b.applied_force(7) == Vec3<float>{0, 1, 0});
  // Reading past the set is an error, with the force arrays made or not (it read past them).
  CHECK_THROWS_AS(b.applied_force(b.size()), Error);
  CHECK_THROWS_AS(b.applied_force(1000000000), Error);
  b.clear_forces();
  CHECK_THROWS_AS(b.applied_force(b.size()), Error);
  RigidBodySet<float> r;
  r.add({});
  r.apply_torque(0, {1, 0, 0});
  CHECK(r.applied_torque(0) == Vec3<float>{1, 0, 0});
  CHECK_THROWS_AS(r.applied_torque(1), Error);
  CHECK_THROWS_AS(r.applied_force(1), Error);
}

TEST_CASE("applied forces move with their body on removal and copy with the set", "[bodies][applied]") {
  ParticleSet<double> b;
  for (int i = 0; i < 4; ++i) b.add({double(i), 0, 0}, {}, 1);
  b.apply_force(3, {0, 0, 7});
  b.remove(1);  // body 3 moves into 1
  CHECK(b.applied_force(1) == Vec3<double>{0, 0, 7});
  CHECK(b.applied_force_data(2)[3] == 0);  // the freed slot is inert padding again
  ParticleSet<double> copy;
  copy = b;
  CHECK(copy.applied_force(1) == Vec3<double>{0, 0, 7});
  ParticleSet<double> moved = std::move(copy);
  CHECK(moved.applied_force(1) == Vec3<double>{0, 0, 7});
  CHECK_FALSE(copy.has_applied_forces());
}

TEST_CASE("a copy into a larger set keeps force arrays as long as that set", "[bodies][applied]") {
  ParticleSet<float> small;
  for (int i = 0; i < 3; ++i) small.add({float(i), 0, 0}, {}, 1);
  small.apply_force(2, {0, 4, 0});
  for (bool had_forces : {false, true}) {
    INFO("the larger set had force arrays: " << had_forces);
    ParticleSet<float> large = test::cloud<float>(5000);
    if (had_forces) large.apply_force(0, {1, 1, 1}), large.clear_forces();
    large = small;  // in place where large's arrays fit, else a new copy
    for (int i = 0; i < 4000; ++i) large.add({0, float(i), 0}, {}, 1);  // past small's capacity
    large.apply_force(4002, {1, 0, 0});
    large.remove(1);  // the last body, 4002, moves into 1 with its force
    Stepper<float>(ForceModel<float>{}, rk4, test::serial_options()).step(large, 0.5f);
    CHECK(large.velocity(2)[1] == 2);  // body 2's force: a = F / m over h
    CHECK(large.velocity(1)[0] == 0.5f);
    CHECK(large.velocity(1000)[0] == 0);
  }
}

TEST_CASE("bad applied forces are refused by body and field", "[bodies][applied][errors]") {
  ParticleSet<float> b;
  b.add({0, 0, 0}, {}, 1);
  const float inf = std::numeric_limits<float>::infinity();
  CHECK_THROWS_WITH(b.apply_force(0, {0, inf, 0}), Catch::Contains("body 0") && Catch::Contains("force"));
  CHECK_THROWS_WITH(b.apply_force(3, {0, 1, 0}), Catch::Contains("body 3: no such body"));
  CHECK_THROWS_WITH(b.apply_impulse(0, {NAN, 0, 0}), Catch::Contains("impulse"));
  b.apply_force(0, {3e38f, 0, 0});
  CHECK_THROWS_WITH(b.apply_force(0, {3e38f, 0, 0}), Catch::Contains("summed"));
  CHECK(b.applied_force(0)[0] == 3e38f);  // the refused one changed nothing
  RigidBodySet<float> r;
  r.add({});
  CHECK_THROWS_WITH(r.apply_torque(0, {inf, 0, 0}), Catch::Contains("torque"));
  CHECK_THROWS_WITH(r.apply_force_at(0, {1, 0, 0}, {0, NAN, 0}), Catch::Contains("point"));
}

TEST_CASE("the fused and staged paths give applied forces the same bits", "[determinism][applied]") {
  for (bool central : {false, true}) {
    for (const Method* m : builtin_methods) {
      auto run = [&](bool staged) {
        ParticleSet<float> b = test::cloud<float>(3000);
        StepperOptions o = test::serial_options();
        o.force_staged = staged;
        Stepper<float> s(test::all_local_terms<float>(true, central), *m, o);
        apply_game_forces(b);
        s.advance(b, 0.01f, 5);
        return test::state_hash(b);
      };
      INFO(m->name << " central " << central);
      CHECK(run(false) == run(true));
    }
  }
}

// Without springs, whose stage forces the fused kernels form from the step's start, the block
// path's stages are the fused kernels' to the bit.
TEST_CASE("a callback's force gives the bits of the same force applied", "[determinism][callbacks]") {
  for (bool central : {false, true}) {
    for (const Method* m : builtin_methods) {
      ParticleSet<float> applied = test::cloud<float>(3000), called_back = applied;
      apply_game_forces(applied);
      ForceModel<float> f;
      f.add(Gravity{{0.1, -9.81, 0.2}}).add(LinearDrag{0.3}).add(QuadraticDrag{0.05});
      if (central) f.add(Central{{7, 3, -5}, 4});
      Stepper<float> fused(f, *m, test::serial_options());
      f.add([](const ParticleBlock<float>& b) {
        for (std::size_t k = 0; k < b.count; ++k) {
          if ((b.begin + k) % 3 != 0) continue;
          const Vec3<float> F = game_force<float>(b.begin + k);
          b.fx[k] += F[0], b.fy[k] += F[1], b.fz[k] += F[2];
        }
      });
      Stepper<float> block(f, *m, test::serial_options());
      REQUIRE(fused.fused());
      fused.advance(applied, 0.01f, 7);
      block.advance(called_back, 0.01f, 7);
      INFO(m->name << " central " << central);
      CHECK(test::state_hash(applied) == test::state_hash(called_back));
    }
  }
}

TEST_CASE("applied forces: the same bits on every ISA, thread count and job system", "[determinism][applied]") {
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t n) {
          ParticleSet<float> b = test::cloud<float>(n);
          Stepper<float> s(test::all_local_terms<float>(true, false), *m, o);
          apply_game_forces(b);
          s.advance(b, 0.01f, 10);
          return test::state_hash(b);
        },
        2000, 9000);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t n) {
          RigidBodySet<float> b;
          for (std::size_t i = 0; i < n; ++i) {
            b.add({{float(i % 10), float(i % 7), 0}, {}, {1, 0.1f * float(i % 4), 0, 0.2f}, {0.1f, 0, 0.3f}, 1 + float(i % 3), {1, 2, 3}});
            if (i % 3 == 0) b.apply_force_at(i, game_force<float>(i), {1, 1, 1});
            if (i % 4 == 0) b.apply_torque(i, {0.5f, -0.25f, 1});
          }
          Stepper<float> s(test::all_local_terms<float>(), *m, o);
          s.advance(b, 0.01f, 10);
          return test::state_hash(b);
        },
        2000, 9000);
  }
}

TEST_CASE("apply_force_at off the centre turns a body at rest about r x F at rate tau / I", "[rigid][applied]") {
  const double m = 2, I = 0.5, h = 0.001;
  const int n = 100;
  RigidBodySet<double> b = sphere_at_rest(m, I);
  const Vec3<double> F{0, 3, 0}, at{1.5, 2, 3};  // r = (0.5, 0, 0): tau = r x F = (0, 0, 1.5)
  b.apply_force_at(0, F, at);
  CHECK(b.applied_torque(0) == Vec3<double>{0, 0, 1.5});
  Stepper<double> s(ForceModel<double>{}, rk4, test::serial_options());
  s.advance(b, h, n);
  const double t = n * h;
  const Vec3<double> w = b.angular_velocity(0);
  CHECK(w[2] == Approx(1.5 * t / I).epsilon(1e-12));  // about z, at the rate tau / I
  CHECK(std::abs(w[0]) + std::abs(w[1]) < 1e-15);
  CHECK(b.angular_momentum(0)[2] == Approx(1.5 * t).epsilon(1e-12));
  CHECK(b.centers().position(0)[1] == Approx(2 + 3 * t * t / (2 * m)).epsilon(1e-13));
  // A sphere under a constant torque turns by tau t^2 / 2I: q = (cos(a/2), 0, 0, sin(a/2)).
  const double angle = 1.5 * t * t / (2 * I);
  CHECK(b.orientation(0)[3] == Approx(std::sin(angle / 2)).epsilon(1e-9));
  CHECK_FALSE(b.has_applied_forces());
}

TEST_CASE("rigid impulses change momentum and angular momentum at once, kinematic bodies ignore them",
          "[rigid][applied]") {
  RigidBodySet<double> b = sphere_at_rest(4, 1);
  b.apply_impulse_at(0, {0, 0, 8}, {1, 3, 3});  // r = (0, 1, 0): r x J = (8, 0, 0)
  CHECK(b.centers().velocity(0) == Vec3<double>{0, 0, 2});
  CHECK(b.angular_momentum(0) == Vec3<double>{8, 0, 0});
  b.apply_angular_impulse(0, {0, -1, 0});
  CHECK(b.angular_momentum(0) == Vec3<double>{8, -1, 0});
  b.set_kinematic(0);
  b.apply_angular_impulse(0, {5, 5, 5});
  b.apply_impulse(0, {5, 5, 5});
  b.apply_torque(0, {5, 5, 5});
  CHECK(b.angular_momentum(0) == Vec3<double>{8, -1, 0});
  CHECK(b.centers().velocity(0) == Vec3<double>{0, 0, 2});
  Stepper<double>(ForceModel<double>{}, rk4, test::serial_options()).advance(b, 0.1, 3);
  CHECK(b.angular_momentum(0) == Vec3<double>{8, -1, 0});
}

TEST_CASE("an applied torque under kick-drift methods grows L linearly", "[rigid][applied]") {
  for (const Method* m : {&symplectic_euler, &velocity_verlet}) {
    INFO(m->name);
    RigidBodySet<double> b = sphere_at_rest(1, 2);
    b.keep_forces(true);
    b.apply_torque(0, {0, 0.5, 0});
    Stepper<double>(ForceModel<double>{}, *m, test::serial_options()).advance(b, 0.01, 50);
    CHECK(b.angular_momentum(0)[1] == Approx(0.25).epsilon(1e-13));
    CHECK(b.has_applied_forces());
  }
}

TEST_CASE("error control steps applied forces too", "[adaptive][applied]") {
  ParticleSet<double> b;
  b.add({0, 0, 0}, {1, 0, 0}, 2);
  b.apply_force(0, {0, 4, 0});
  Stepper<double> s(ForceModel<double>{}, dopri5, test::serial_options());
  s.advance_to(b, 1.5, Tolerances{1e-9, 1e-9});
  CHECK(b.position(0)[1] == Approx(4 * 1.5 * 1.5 / 4).epsilon(1e-12));
  CHECK(b.position(0)[0] == Approx(1.5).epsilon(1e-12));
  CHECK_FALSE(b.has_applied_forces());
}

namespace {

// Gravity and a pull toward the origin given by a callback, the rest built in.
template <class T>
ForceModel<T> callback_model(bool with_callback) {
  ForceModel<T> f;
  f.add(LinearDrag{0.3}).add(QuadraticDrag{0.05});
  if (!with_callback) return f.add(Gravity{{0.5, -9.81, 0}}).add(Spring{{0, 0, 0}, 2, 0});
  return f.add([](const ParticleBlock<T>& b) {
    for (std::size_t i = 0; i < b.count; ++i) {
      const T m = b.mass[i];
      b.fx[i] += T(0.5) * m - 2 * b.px[i], b.fy[i] += T(-9.81) * m - 2 * b.py[i], b.fz[i] -= 2 * b.pz[i];
    }
  });
}

// Counts the views it is given and the bodies whose mass is not 1 / inv_mass (0 where
// inv_mass is 0), for callbacks and coupled terms alike; views come concurrently.
struct MassCheck {
  std::size_t bodies = 0;  // the set's: views past it are padding
  std::shared_ptr<std::atomic<long>> views = std::make_shared<std::atomic<long>>(0);
  std::shared_ptr<std::atomic<long>> wrong = std::make_shared<std::atomic<long>>(0);
  std::shared_ptr<std::atomic<long>> padding = std::make_shared<std::atomic<long>>(0);
  std::shared_ptr<std::atomic<long>> later_blocks = std::make_shared<std::atomic<long>>(0);
  template <class View>
  void operator()(const View& b) const {
    ++*views;
    *later_blocks += b.begin >= kBlockBodies;
    for (std::size_t i = 0; i < b.count; ++i) {
      *padding += b.begin + i >= bodies;
      *wrong += b.mass[i] != (b.inv_mass[i] == 0 ? 0 : 1 / b.inv_mass[i]);
    }
  }
};

class MassCheckTerm final : public CoupledTerm<double> {
 public:
  explicit MassCheckTerm(MassCheck check) : check_(std::move(check)) {}
  void accumulate(const ParticleState<double>&, const ParticleBlock<double>& b) const override { check_(b); }
  double potential_energy(const ParticleState<double>&) const override { return 0; }

 private:
  MassCheck check_;
};

}  // namespace

TEST_CASE("the block path: a callback moves bodies as the equivalent built-in terms do", "[forces][callbacks]") {
  for (const Method* m : builtin_methods) {
    INFO(m->name);
    ParticleSet<double> a = test::cloud<double>(3000), b = a;
    Stepper<double> built_in(callback_model<double>(false), *m, test::serial_options());
    Stepper<double> by_callback(callback_model<double>(true), *m, test::serial_options());
    REQUIRE(built_in.fused());
    built_in.advance(a, 0.01, 50);
    by_callback.advance(b, 0.01, 50);
    double worst = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
      worst = std::max(worst, test::distance(a.position(i), b.position(i)) + test::distance(a.velocity(i), b.velocity(i)));
    }
    CHECK(worst < 1e-11);
  }
}

TEST_CASE("a view's mass is 1 / inv_mass, 0 for kinematic and padding bodies, on every path", "[forces][callbacks]") {
  // The block path, the staged path's callbacks and coupled terms, rigid centres' coupled
  // terms, rigid callbacks, on three blocks and two threads; a kinematic body (index 7) and
  // one made kinematic between the two calls (index 1500), whose mass the second call sees.
  constexpr std::size_t kBodies = 2500;  // and padding
  for (const Method* m : {&rk4, &velocity_verlet}) {
    for (const int kind : {0, 1, 2, 3, 4}) {
      INFO(m->name << ", kind " << kind);
      MassCheck check;
      check.bodies = kBodies;
      ForceModel<double> f;
      if (kind < 2) f.add(ForceCallback<double>(check));
      if (kind == 2 || kind == 3) f.add(std::make_shared<const MassCheckTerm>(check));
      if (kind == 4) f.add(RigidCallback<double>(check));
      StepperOptions o;
      o.threads = 2;
      o.force_staged = kind == 1;
      Stepper<double> s(f, *m, o);
      auto run = [&](auto& b) {
        b.set_kinematic(7);
        s.advance(b, 0.01, 3);
        b.set_kinematic(1500);
        s.advance(b, 0.01, 3);
      };
      if (kind >= 3) {
        RigidBodySet<double> r = test::tumbling_cloud<double>(kBodies);
        run(r);
      } else {
        ParticleSet<double> b = test::cloud<double>(kBodies);
        run(b);
      }
      CHECK(*check.views > 0);
      CHECK(*check.later_blocks > 0);
      CHECK(*check.padding > 0);
      CHECK(*check.wrong == 0);
    }
  }
  // Error control (its first stage reused from the step before) and the acceleration probe.
  MassCheck check;
  check.bodies = kBodies;
  ForceModel<double> f;
  f.add(ForceCallback<double>(check));
  Stepper<double> s(f, dopri5, test::serial_options());
  ParticleSet<double> b = test::cloud<double>(kBodies);
  s.advance_to(b, 0.05, Tolerances{1e-6, 1e-6});
  b.set_kinematic(1500);
  s.advance_to(b, 0.1, Tolerances{1e-6, 1e-6});
  const long before_probe = *check.views;
  std::vector<double> ax(b.padded_size()), ay(ax), az(ax);
  double* const out[3] = {ax.data(), ay.data(), az.data()};
  s.accelerations(b, 0.1, out);
  CHECK(*check.views > before_probe);
  CHECK(*check.wrong == 0);
}

TEST_CASE("the block paths read applied forces and torques", "[forces][callbacks]") {
  ParticleSet<double> a = test::cloud<double>(2000), b = a;
  for (ParticleSet<double>* set : {&a, &b}) set->keep_forces(true), apply_game_forces(*set);
  Stepper<double> built_in(callback_model<double>(false), rk4, test::serial_options());
  Stepper<double> by_callback(callback_model<double>(true), rk4, test::serial_options());
  built_in.advance(a, 0.01, 30);
  by_callback.advance(b, 0.01, 30);
  for (std::size_t i = 0; i < a.size(); ++i) CHECK(test::distance(a.velocity(i), b.velocity(i)) < 1e-11);

  RigidBodySet<double> r, s;
  for (RigidBodySet<double>* set : {&r, &s}) {
    set->add({{0, 0, 0}, {}, {1, 0, 0, 0}, {}, 2, {0.5, 1, 2}});
    set->keep_forces(true);
    set->apply_force_at(0, {0, 3, 0}, {0.5, 0, 0});  // and the torque (0, 0, 1.5)
  }
  ForceModel<double> idle;
  idle.add([](const RigidBlock<double>&) {});  // takes the rigid block path, adds nothing
  Stepper<double>(ForceModel<double>{}, rk4, test::serial_options()).advance(r, 0.01, 50);
  Stepper<double>(idle, rk4, test::serial_options()).advance(s, 0.01, 50);
  CHECK(s.angular_momentum(0)[2] == Approx(1.5 * 0.5).epsilon(1e-12));
  CHECK(s.centers().velocity(0)[1] == Approx(3 * 0.5 / 2).epsilon(1e-12));
  CHECK(s.angular_velocity(0)[2] == Approx(r.angular_velocity(0)[2]).epsilon(1e-12));
}

TEST_CASE("the block path: the same bits on every ISA, thread count and job system", "[determinism][callbacks]") {
  for (const Method* m : {&rk4, &midpoint, &velocity_verlet}) {
    INFO(m->name);
    test::check_same_bits_everywhere(
        [&](StepperOptions o, std::size_t n) {
          ParticleSet<float> b = test::cloud<float>(n);
          apply_game_forces(b);
          ForceModel<float> f = callback_model<float>(true);
          f.add(Central{{7, 3, -5}, 4});
          Stepper<float> s(f, *m, o);
          s.advance(b, 0.01f, 10);
          return test::state_hash(b);
        },
        2000, 9000);
  }
}
