// Methods as data: the tableaus satisfy their order conditions; lookups and validation.
#include <catch2/catch.hpp>

#include <vector>

#include "kinema/error.hpp"
#include "kinema/methods.hpp"

using namespace kinema;

TEST_CASE("every tableau is consistent: sum b = 1 and c_i = sum_j a_ij", "[methods]") {
  std::vector<const Method*> all(builtin_methods.begin(), builtin_methods.end());
  all.insert(all.end(), staged_methods.begin(), staged_methods.end());
  for (const Method* m : all) {
    if (m->kind != MethodKind::runge_kutta) continue;
    const auto& t = m->tableau;
    double sum_b = 0;
    for (int i = 0; i < t.stages; ++i) {
      sum_b += t.b[i];
      double row = 0;
      for (int j = 0; j < i; ++j) row += t.a[i][j];
      INFO(m->name << " stage " << i);
      CHECK(row == Approx(t.c[i]));
    }
    CHECK(sum_b == Approx(1.0));
    if (m->embedded_order > 0) {
      double sum_b_hat = 0;
      for (int i = 0; i < t.stages; ++i) sum_b_hat += t.b_hat[i];
      CHECK(sum_b_hat == Approx(1.0));
    }
  }
  // The embedded pairs reuse their last stage as the next step's first.
  CHECK(bs3.tableau.first_same_as_last());
  CHECK(dopri5.tableau.first_same_as_last());
  CHECK_FALSE(rk4.tableau.first_same_as_last());
  CHECK_FALSE(rk6.tableau.first_same_as_last());
}

TEST_CASE("rk4's tableau meets the fourth-order conditions", "[methods]") {
  const auto& t = rk4.tableau;
  double bc = 0, bc2 = 0, bc3 = 0, bac = 0, bcac = 0, bac2 = 0, baac = 0;
  for (int i = 0; i < 4; ++i) {
    bc += t.b[i] * t.c[i];
    bc2 += t.b[i] * t.c[i] * t.c[i];
    bc3 += t.b[i] * t.c[i] * t.c[i] * t.c[i];
    for (int j = 0; j < 4; ++j) {
      bac += t.b[i] * t.a[i][j] * t.c[j];
      bcac += t.b[i] * t.c[i] * t.a[i][j] * t.c[j];
      bac2 += t.b[i] * t.a[i][j] * t.c[j] * t.c[j];
      for (int k = 0; k < 4; ++k) baac += t.b[i] * t.a[i][j] * t.a[j][k] * t.c[k];
    }
  }
  CHECK(bc == Approx(1.0 / 2));
  CHECK(bc2 == Approx(1.0 / 3));
  CHECK(bac == Approx(1.0 / 6));
  CHECK(bc3 == Approx(1.0 / 4));
  CHECK(bcac == Approx(1.0 / 8));
  CHECK(bac2 == Approx(1.0 / 12));
  CHECK(baac == Approx(1.0 / 24));
}

TEST_CASE("methods are found by name, and unknown names list the known ones", "[methods][errors]") {
  for (const Method* m : builtin_methods) {
    CHECK(&method_by_name(m->name) == m);
    CHECK(builtin_index(*m) >= 0);
  }
  for (const Method* m : staged_methods) {
    CHECK(&method_by_name(m->name) == m);
    CHECK(builtin_index(*m) == -1);
    CHECK_NOTHROW(validate(*m));
  }
  for (const Method* m : implicit_methods) {
    CHECK(&method_by_name(m->name) == m);
    CHECK(builtin_index(*m) == -1);
    CHECK_NOTHROW(validate(*m));
  }
  CHECK_THROWS_WITH(method_by_name("rk5"),
                    "unknown method 'rk5' (known: euler, midpoint, heun, rk4, "
                    "symplectic_euler, velocity_verlet, bs3, dopri5, rk6, implicit_euler, ros2)");
}

TEST_CASE("invalid Rosenbrock schemes are refused", "[methods][errors][implicit]") {
  Method m = ros2;
  m.rosenbrock.gamma = 0;
  CHECK_THROWS_WITH(validate(m), Catch::Contains("gamma must be finite and > 0"));
  m = ros2;
  m.rosenbrock.c[0][1] = 1;
  CHECK_THROWS_WITH(validate(m), Catch::Contains("strictly lower triangular"));
  m = implicit_euler;
  m.rosenbrock.m[1] = 0.5;
  CHECK_THROWS_WITH(validate(m), Catch::Contains("beyond the last stage"));
  m = ros2;
  m.rosenbrock.stages = 3;
  CHECK_THROWS_WITH(validate(m), Catch::Contains("1..2 stages"));
}

TEST_CASE("invalid user methods are refused", "[methods][errors]") {
  Method upper = rk4;
  upper.name = "upper";
  upper.tableau.a[0][1] = 1;
  CHECK_THROWS_WITH(validate(upper), Catch::Contains("strictly lower triangular"));
  Method big = rk4;
  big.name = "big";
  big.tableau.stages = 8;
  CHECK_THROWS_WITH(validate(big), Catch::Contains("method 'big': stages must be 1..7"));
  Method half_pair = rk4;
  half_pair.name = "half_pair";
  half_pair.tableau.b_hat = {0.5, 0.5};
  CHECK_THROWS_WITH(validate(half_pair), Catch::Contains("b_hat and embedded_order go together"));
  Method empty = symplectic_euler;
  empty.name = "empty";
  empty.scheme.count = 0;
  CHECK_THROWS_AS(validate(empty), Error);
  CHECK(rk4.evaluations() == 4);
  CHECK(velocity_verlet.evaluations() == 2);
  CHECK(symplectic_euler.evaluations() == 1);
}
