// Every registered force term, walked through its home (src/forces/force_terms.hpp): a scene can
// spell it, the model validates it, its potential agrees with the force the kernels apply
// (or it says it has none), and its reference rule gives the motion a fine rk4 run finds.
#include <catch2/catch.hpp>

#include <set>
#include <string>

#include "forces/force_terms.hpp"
#include "support.hpp"

using namespace kinema;

namespace {

// A scene's spelling of the term with every field but `without`: vectors (0.5, -0.25, 0.75),
// numbers 0.5.
template <class Term>
std::string term_json(const std::string& without = "") {
  std::string json = "{\"type\": \"" + std::string(TermInfo<Term>::name) + "\"";
  for_each_field(TermInfo<Term>{}, [&](const auto& field) {
    if (field.key == without) return;
    json += ", \"" + std::string(field.key) + "\": ";
    json += std::decay_t<decltype(field)>::is_vector ? "[0.5, -0.25, 0.75]" : "0.5";
  });
  return json + "}";
}

Scene one_body(const std::string& force, const Vec3<double>& x, const Vec3<double>& v) {
  char body[256];
  std::snprintf(body, sizeof body, R"({"position": [%.17g, %.17g, %.17g], "velocity": [%.17g, %.17g, %.17g], "mass": 2})",
                x[0], x[1], x[2], v[0], v[1], v[2]);
  return parse_scene(std::string(R"({"precision": "double", "particles": [)") + body +
                     R"(], "forces": [)" + force + "]}");
}

// The acceleration the kernels apply at x, from rest: one rk4 step of h from x is
// x + a h^2 / 2 + O(h^4) for a position-only force.
Vec3<double> kernel_acceleration(const Scene& scene) {
  const double h = 1e-4;
  World<double> world(scene, rk4, on_calling_thread());
  const Vec3<double> x0 = world.particles.position(0);
  world.advance(h, 1);
  const Vec3<double> x1 = world.particles.position(0);
  return {2 * (x1[0] - x0[0]) / (h * h), 2 * (x1[1] - x0[1]) / (h * h), 2 * (x1[2] - x0[2]) / (h * h)};
}

template <class Term>
void check_potential(const Term& term) {
  using Info = TermInfo<Term>;
  const Vec3<double> x{1.5, -0.5, 2.0};
  const double mass = 2, e = 1e-6;
  Vec3<double> force{};  // -grad U by central differences
  for (int d = 0; d < 3; ++d) {
    Vec3<double> up = x, down = x;
    up[d] += e, down[d] -= e;
    force[d] = -(Info::potential(term, up, mass) - Info::potential(term, down, mass)) / (2 * e);
  }
  const Vec3<double> a = kernel_acceleration(one_body(term_json<Term>(), x, {0, 0, 0}));
  // Loose enough for the estimate's O(h) from a spring's damping; a wrong sign, factor or
  // mass fails by far.
  for (int d = 0; d < 3; ++d) CHECK(a[d] == Approx(force[d] / mass).epsilon(1e-3).margin(1e-6));
}

// The reference rule against a fine rk4 run of one body under the term alone.
template <class Term>
void check_reference(const std::string& force) {
  using Info = TermInfo<Term>;
  const Scene scene = one_body(force, {1, 0, 0}, {0, 1, 0.2});
  const double duration = 2;
  const auto exact = analytic_states(scene, duration);
  if constexpr (Info::reference == ReferenceRule::none) {
    CHECK_FALSE(exact);
  } else {
    REQUIRE(exact);
    CHECK(state_error(*exact, simulate(scene, rk4, 20000, duration)) < 1e-9);
  }
}

}  // namespace

TEST_CASE("every force term has a name, fields, a potential or none, and a reference rule", "[forces][terms]") {
  std::set<std::string> names;
  int terms = 0;
  for_each_term([&]<class Term>() {
    using Info = TermInfo<Term>;
    INFO(Info::name);
    ++terms;
    CHECK(names.insert(std::string(Info::name)).second);  // unique
    // A scene spells it, with every field, and reads back what it wrote.
    const Scene scene = one_body(term_json<Term>(), {1, 0, 0}, {0, 0, 0});
    REQUIRE(scene.forces.size() == 1);
    REQUIRE(std::holds_alternative<Term>(scene.forces[0]));
    CHECK(term_name(scene.forces[0]) == Info::name);
    CHECK(acts_on_rigid_bodies_only(scene.forces[0]) == (Info::kind == TermKind::rotational));
    const Term& parsed = std::get<Term>(scene.forces[0]);
    for_each_field(Info{}, [&](const auto& field) {
      INFO(field.key);
      if constexpr (std::decay_t<decltype(field)>::is_vector) {
        CHECK((parsed.*field.member == Vec3<double>{0.5, -0.25, 0.75}));
      } else {
        CHECK(parsed.*field.member == 0.5);
        // The model refuses it out of range, naming the term and the field.
        Term bad = parsed;
        bad.*field.member = -1;
        CHECK_THROWS_WITH(ForceModel<double>().add(bad),
                          std::string(Info::name) + "." + field.key + ": must be finite and >= 0");
      }
      if (field.required) {  // and a scene without it names the key
        CHECK_THROWS_WITH(one_body(term_json<Term>(field.key), {1, 0, 0}, {0, 0, 0}),
                          Catch::Contains("forces[0]: missing key '" + std::string(field.key) + "'"));
      }
    });
    // The potential agrees with the force on a particle, or the term says it has none.
    if constexpr (Info::has_potential) check_potential(parsed);
    // The reference rule holds for a particle under the term alone.
    check_reference<Term>(term_json<Term>());
    // A local term moves a particle; a rotational one leaves it to move freely.
    const Scene alone = one_body(term_json<Term>(), {1, 0, 0}, {0, 1, 0.2});
    const Scene free = one_body("", {1, 0, 0}, {0, 1, 0.2});
    const bool moves = state_error(simulate(alone, rk4, 10, 1), simulate(free, rk4, 10, 1)) > 0;
    CHECK(moves == (Info::kind == TermKind::local));
  });
  CHECK(terms == int(std::variant_size_v<LocalTerm>));
}
