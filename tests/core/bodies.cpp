// ParticleSet storage: alignment, padding with inert bodies, growth, validation.
#include <catch2/catch.hpp>

#include <cstdint>
#include <limits>
#include <set>

#include "support.hpp"

using namespace kinema;

TEMPLATE_TEST_CASE("arrays are 64-byte aligned and padded to whole lines", "[bodies]", float,
                   double) {
  ParticleSet<TestType> set;
  constexpr std::size_t lane = 64 / sizeof(TestType);
  for (std::size_t n = 1; n <= 3 * lane + 1; ++n) {
    set.add({TestType(n), 0, 0}, {0, 0, 0}, 1);
    REQUIRE(set.size() == n);
    REQUIRE(set.padded_size() % lane == 0);
    REQUIRE(set.padded_size() >= n);
    REQUIRE(set.padded_size() < n + lane);
    const auto& view = set;
    for (const TestType* a : {view.px(), view.py(), view.pz(), view.vx(), view.vy(), view.vz(),
                              view.inv_mass()}) {
      REQUIRE(reinterpret_cast<std::uintptr_t>(a) % 64 == 0);
    }
  }
}

TEMPLATE_TEST_CASE("a large set's arrays sit at distinct offsets within a page", "[bodies]",
                   float, double) {
  ParticleSet<TestType> set = test::cloud<TestType>(100000);
  ParticleSet<TestType> copy = set;  // copies place their arrays the same way
  for (const ParticleSet<TestType>* s : {&set, &copy}) {
    std::set<std::uintptr_t> offsets;
    for (const TestType* a : {s->px(), s->py(), s->pz(), s->vx(), s->vy(), s->vz(), s->inv_mass()}) {
      REQUIRE(reinterpret_cast<std::uintptr_t>(a) % 64 == 0);
      offsets.insert(reinterpret_cast<std::uintptr_t>(a) % 4096);
    }
    CHECK(offsets.size() == 7);
  }
  CHECK(test::state_hash(copy) == test::state_hash(set));
}

TEMPLATE_TEST_CASE("a moved-from set is empty and takes new bodies", "[bodies]", float, double) {
  ParticleSet<TestType> from = test::cloud<TestType>(100);
  const std::uint64_t hash = test::state_hash(from);
  ParticleSet<TestType> to = std::move(from);
  CHECK(test::state_hash(to) == hash);
  CHECK(from.size() == 0);
  CHECK(from.padded_size() == 0);
  from.add({1, 2, 3}, {0, 0, 0}, 1);
  CHECK(from.size() == 1);
  CHECK(from.position(0) == Vec3<TestType>{1, 2, 3});
}

TEMPLATE_TEST_CASE("padding bodies are inert and stay put", "[bodies]", float, double) {
  ParticleSet<TestType> set;
  set.add({1, 2, 3}, {4, 5, 6}, 2);
  REQUIRE(set.padded_size() > 1);
  Stepper<TestType> s(test::all_local_terms<TestType>(), rk4, test::serial_options());
  s.advance(set, TestType(0.01), 10);
  for (std::size_t i = 1; i < set.padded_size(); ++i) {
    CHECK(set.inv_mass()[i] == 0);
    CHECK(set.px()[i] == 0);
    CHECK(set.vx()[i] == 0);
  }
  CHECK(set.inv_mass()[0] == TestType(0.5));
}

TEST_CASE("bulk add and one-by-one add build the same set", "[bodies]") {
  std::vector<ParticleDesc<double>> descs;
  ParticleSet<double> one;
  for (int i = 0; i < 100; ++i) {
    descs.push_back({{double(i), 1, 2}, {0, double(-i), 0}, 1.0 + i});
    one.add(descs.back());
  }
  ParticleSet<double> bulk;
  bulk.add(std::span<const ParticleDesc<double>>(descs));
  CHECK(test::state_hash(bulk) == test::state_hash(one));
  ParticleSet<double> copy = bulk;
  CHECK(test::state_hash(copy) == test::state_hash(bulk));
  CHECK(copy.px() != bulk.px());
}

TEST_CASE("an orientation of any finite size is normalized: only zero is refused", "[bodies][rigid]") {
  RigidBodySet<double> set;
  const double tiny = 1e-200, huge = 1e300;
  // Squares past double's range: (1e300)^2 is inf and (1e-200)^2 is 0.
  for (const Quat<double>& q : {Quat<double>{huge, 0, 0, huge}, Quat<double>{tiny, tiny, 0, 0},
                                Quat<double>{0, 3 * huge, 4 * huge, 0}, Quat<double>{1e-160, 0, 0, 0},
                                Quat<double>{2e-162, 2e-162, 0, 0}}) {  // the last two: subnormal squares
    const std::size_t i = set.add({.orientation = q});
    const Quat<double> added = set.orientation(i);
    set.set_orientation(i, {1, 0, 0, 0});
    set.set_orientation(i, q);
    CHECK(set.orientation(i) == added);
    double norm = 0;
    for (double c : added) norm += c * c;
    CHECK(norm == Approx(1).epsilon(1e-15));
    for (int k = 0; k < 4; ++k) CHECK((added[k] == 0) == (q[k] == 0));
  }
  CHECK(set.orientation(2)[1] == Approx(0.6));  // (0, 3, 4, 0) / 5
  CHECK(set.orientation(0)[0] == Approx(std::sqrt(0.5)));
  CHECK_THROWS_WITH(set.add({.orientation = {0, 0, 0, 0}}), Catch::Contains("orientation quaternion is zero"));
  CHECK_THROWS_WITH(set.set_orientation(0, {0, 0, 0, 0}), Catch::Contains("orientation quaternion is zero"));
  CHECK(set.size() == 5);
}

TEST_CASE("bad bodies are refused with the body and field named", "[bodies][errors]") {
  ParticleSet<float> set;
  set.add({0, 0, 0}, {0, 0, 0}, 1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  CHECK_THROWS_WITH(set.add({0, nan, 0}, {0, 0, 0}, 1), "body 1: position is not finite");
  CHECK_THROWS_WITH(set.add({0, 0, 0}, {inf, 0, 0}, 1), "body 1: velocity is not finite");
  CHECK_THROWS_WITH(set.add({0, 0, 0}, {0, 0, 0}, -1),
                    Catch::Contains("body 1: mass must be positive and finite"));
  CHECK_THROWS_WITH(set.add({0, 0, 0}, {0, 0, 0}, 0), Catch::Contains("body 1: mass"));
  CHECK_THROWS_WITH(set.add({0, 0, 0}, {0, 0, 0}, inf), Catch::Contains("body 1: mass"));
  CHECK_THROWS_WITH(set.add({0, 0, 0}, {0, 0, 0}, nan), Catch::Contains("body 1: mass"));
  CHECK_THROWS_WITH(set.set_velocity(0, {nan, 0, 0}), "body 0: velocity is not finite");
  CHECK_THROWS_WITH(set.set_position(5, {0, 0, 0}), "body 5: no such body (the set has 1)");
  CHECK(set.size() == 1);  // nothing half-added
  // Many at once: all or none, the refused one named by the index it would have had.
  const std::vector<ParticleDesc<float>> four = {{{1, 0, 0}, {}, 1}, {{2, 0, 0}, {}, 1}, {{3, 0, 0}, {}, -1}, {{4, 0, 0}, {}, 1}};
  const std::uint64_t before = test::state_hash(set);
  CHECK_THROWS_WITH(set.add(std::span<const ParticleDesc<float>>(four)), Catch::Contains("body 3: mass"));
  CHECK(set.size() == 1);
  CHECK(test::state_hash(set) == before);
  // A count no array can hold, for a set and for a stepper's scratch (padded, it would wrap to 0).
  const std::size_t most = std::numeric_limits<std::size_t>::max();
  CHECK_THROWS_WITH(set.reserve(most), Catch::Contains("the arrays would overflow memory"));
  ForceModel<float> springs;
  springs.add(Springs{{{0, 1, 1, 1, 0}}});
  Stepper<float> stepper(springs, rk4);
  CHECK_THROWS_WITH(stepper.reserve(most), Catch::Contains("the arrays would overflow memory"));
}
