// Set-up errors are kinema::Error with a message naming the culprit; nothing moves.
#include <catch2/catch.hpp>

#include <limits>

#include "support.hpp"

using namespace kinema;

TEST_CASE("bad step sizes are refused before any body moves", "[errors]") {
  ParticleSet<double> b;
  b.add({1, 0, 0}, {0, 1, 0}, 1);
  Stepper<double> s(test::all_local_terms<double>(), rk4, test::serial_options());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (double h : {0.0, -0.01, nan, std::numeric_limits<double>::infinity()}) {
    CHECK_THROWS_WITH(s.step(b, h), Catch::StartsWith("step size h must be positive and finite"));
    CHECK_THROWS_AS(s.advance(b, h, 3), Error);
  }
  CHECK(b.position(0) == Vec3<double>{1, 0, 0});
  CHECK(s.time() == 0);
}

TEST_CASE("bad force parameters name the term and field", "[errors]") {
  ForceModel<float> f;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(f.add(LinearDrag{-1}), "linear_drag.k: must be finite and >= 0");
  CHECK_THROWS_WITH(f.add(QuadraticDrag{nan}), "quadratic_drag.k: must be finite and >= 0");
  CHECK_THROWS_WITH(f.add(Spring{{0, 0, 0}, 1, -2}), "spring.damping: must be finite and >= 0");
  CHECK_THROWS_WITH(f.add(Spring{{0, nan, 0}, 1, 0}), "spring.anchor: must be finite");
  CHECK_THROWS_WITH(f.add(Gravity{{0, nan, 0}}), "gravity.g: must be finite");
  CHECK_THROWS_WITH(f.add(Central{{0, 0, 0}, -1}), "central.mu: must be finite and >= 0");
  for (int i = 0; i < kMaxCentralTerms; ++i) f.add(Central{{double(i), 0, 0}, 1});
  CHECK_THROWS_WITH(f.add(Central{{0, 0, 0}, 1}), "central: at most 4 per model");
  CHECK_THROWS_WITH(f.add(ForceCallback<float>{}), "callback force: empty function");
  CHECK_THROWS_WITH(f.add(std::shared_ptr<const CoupledTerm<float>>{}),
                    "coupled force: null term");
}

TEST_CASE("a step that would scale force parameters past the type's range is refused", "[errors]") {
  ForceModel<float> f;
  f.add(Spring{{0, 0, 0}, 2e38, 0});  // finite in float
  ParticleSet<float> b;
  b.add({1, 0, 0}, {0, 0, 0}, 1);
  b.add_kinematic({2, 0, 0});
  Stepper<float> s(f, rk4, test::serial_options());
  CHECK_THROWS_WITH(s.check_step_size(4.0f), Catch::Contains("overflows float; take a smaller step"));
  CHECK_THROWS_WITH(s.step(b, 4.0f), Catch::Contains("overflows float; take a smaller step"));
  CHECK_THROWS_WITH(s.check_step_size(float(1e-50)), Catch::Contains("got 0"));  // underflowed
  CHECK_NOTHROW(s.check_step_size(1e-20f));
  CHECK(b.position(0) == Vec3<float>{1, 0, 0});
  s.step(b, 1e-20f);  // a step small enough works, and the kinematic body stays finite
  CHECK(all_finite(b));
  CHECK(b.position(1) == Vec3<float>{2, 0, 0});
  // Each rate may fit while a stage's weighted sum of them does not: dopri5's weights add up
  // to about 25 (rk4's to 1). g = 3e37 in one step of 1 s gave dopri5 vy = -inf.
  ForceModel<float> pull;
  pull.add(Gravity{{0, -3e37, 0}});
  for (const Method* m : {&rk4, &dopri5}) {
    ParticleSet<float> falling;
    falling.add({0, 0, 0}, {0, 0, 0}, 1);
    Stepper<float> stepper(pull, *m, test::serial_options());
    if (m == &dopri5) {
      CHECK_THROWS_WITH(stepper.step(falling, 1.0f), Catch::Contains("overflows float; take a smaller step"));
      CHECK(falling.velocity(0) == Vec3<float>{0, 0, 0});
      stepper.step(falling, 1.0f / 16);  // a step whose sums fit
    } else {
      stepper.step(falling, 1.0f);
    }
    CHECK(all_finite(falling));
    CHECK(falling.velocity(0)[1] == Approx(m == &dopri5 ? -3e37 / 16 : -3e37).epsilon(1e-6));
  }
}

TEST_CASE("unknown instruction sets are refused by name", "[errors]") {
  CHECK_THROWS_WITH(isa_by_name("neon"), Catch::StartsWith("unknown isa 'neon'"));
  CHECK(isa_by_name("avx2") == Isa::avx2);
  CHECK(resolve_isa(Isa::automatic) == best_isa());
  CHECK(resolve_isa(Isa::scalar) == Isa::scalar);
}

TEST_CASE("a stepper refuses an invalid method", "[errors]") {
  Method bad = rk4;
  bad.name = "bad";
  bad.tableau.a[1][1] = 0.5;
  CHECK_THROWS_WITH(Stepper<double>(ForceModel<double>{}, bad, test::serial_options()),
                    Catch::Contains("method 'bad'"));
}
