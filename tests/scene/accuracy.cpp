// Reference solutions and the automatic choice of method and step.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "support.hpp"

using namespace kinema;

namespace {

Scene one_body_scene(std::vector<LocalTerm> forces, Vec3<double> x, Vec3<double> v, double mass = 1) {
  Scene s;
  s.precision = Precision::dual;
  s.particles.push_back({x, v, mass, false, {}, {}, {}});
  s.forces = std::move(forces);
  return s;
}

double numerical_error(const Scene& s, double t, std::uint64_t steps) {
  return state_error(simulate(s, rk4, steps, t), *analytic_states(s, t));
}

}  // namespace

TEST_CASE("Kepler's equation gives the orbit: back home after whole periods", "[accuracy]") {
  const Scene circular = one_body_scene({Central{{0, 0, 0}, 1}}, {1, 0, 0}, {0, 1, 0});
  const auto home = analytic_states(circular, 6 * std::numbers::pi);  // three periods
  REQUIRE(home);
  CHECK(state_error(*home, {{{1, 0, 0}}, {{0, 1, 0}}, {}}) < 1e-12);
  // Eccentric, off-centre, tilted: the analytic state agrees with a fine rk4 run.
  const Scene eccentric = one_body_scene({Central{{1, -2, 0.5}, 2}}, {1.4, -2, 0.5}, {0, 2.4, 0.6});
  CHECK(numerical_error(eccentric, 3.7, 40000) < 1e-9);
  // Unbound: no closed form here.
  CHECK_FALSE(analytic_states(one_body_scene({Central{{0, 0, 0}, 1}}, {1, 0, 0}, {0, 2, 0}), 1));
}

TEST_CASE("linear forces have closed forms: under-, over- and critically damped", "[accuracy]") {
  for (double damping : {0.5, 4.0, 8.0, 0.0}) {  // k/m = 4: critical at 4 with m = 1? c = 2 sqrt(k m)
    const Scene s = one_body_scene({Gravity{{0, -9.81, 1}}, Spring{{1, 2, 3}, 4, damping}, LinearDrag{0.3}},
                                   {0.5, 0, 1}, {1, 2, -1}, 1.5);
    INFO("damping " << damping);
    CHECK(numerical_error(s, 2.5, 20000) < 1e-9);
  }
  CHECK(numerical_error(one_body_scene({Gravity{{0, -9.81, 0}}, LinearDrag{0.7}}, {0, 0, 0}, {3, 4, 0}), 2, 20000) < 1e-9);
  CHECK_FALSE(analytic_states(one_body_scene({QuadraticDrag{0.1}}, {0, 0, 0}, {1, 0, 0}), 1));
}

TEST_CASE("the numerical reference estimates its own error", "[accuracy]") {
  const Scene s = one_body_scene({QuadraticDrag{0.2}, Gravity{{0, -9.81, 0}}}, {0, 0, 0}, {10, 10, 0});
  const Reference coarse = reference_states(s, 2, 200), fine = reference_states(s, 2, 20000);
  CHECK_FALSE(coarse.analytic);
  const double true_error = state_error(coarse.states, fine.states);
  CHECK(coarse.error == Approx(true_error).epsilon(0.2));  // Richardson is close to the truth
}

TEST_CASE("the accuracy tools refuse states of different sizes and durations that are not finite", "[accuracy][errors]") {
  // state_error once read past the shorter states (a crash); analytic_states returned NaN
  // states for a NaN duration and a state at t = -1 for -1.
  const BodyStates one{{{0, 0, 0}}, {{0, 0, 0}}, {}}, none{};
  CHECK_THROWS_WITH(state_error(one, none), Catch::Contains("state_error: the states hold 1 bodies (0 orientations), the reference 0"));
  CHECK_THROWS_AS(state_error(none, one), Error);
  CHECK(state_error(one, one) == 0);
  const Scene s = one_body_scene({Spring{{0, 0, 0}, 4, 0.5}}, {1, 0, 0}, {0, 0, 0});
  for (const double t : {std::nan(""), -1.0, std::numeric_limits<double>::infinity()}) {
    INFO(t);
    CHECK_THROWS_WITH(analytic_states(s, t), Catch::Contains("analytic_states: the duration must be finite and >= 0"));
    CHECK_THROWS_AS(reference_states(s, t, 10), Error);
  }
  CHECK(state_error(*analytic_states(s, 0), {{{1, 0, 0}}, {{0, 0, 0}}, {}}) < 1e-15);
}

namespace {

std::string scene_path(const char* name) { return std::string(KINEMA_SCENES) + "/" + name + ".json"; }

}  // namespace

TEST_CASE("auto meets the tolerance on every shipped scene, for no more work than rk4", "[accuracy][auto]") {
  const std::pair<const char*, double> cases[] = {
      {"kepler_circular", 1e-4}, {"kepler_eccentric", 1e-4}, {"damped_spring", 1e-6},
      {"projectiles", 1e-2},     {"drag_field", 1e-3},      {"tumbling_book", 1e-3},
      {"spinning_debris", 1e-2}};
  for (const auto& [name, tolerance] : cases) {
    const Scene scene = load_scene(scene_path(name));
    const double duration = scene.dt * double(scene.steps);
    const MethodChoice choice = choose_method(scene, tolerance);
    INFO(name << ": " << choice.reason);
    REQUIRE(choice.method != nullptr);
    if (!choice.step_tolerance) CHECK(choice.dt * double(choice.steps) == Approx(duration).epsilon(1e-12));
    // Against the reference on the same sample of bodies the pilots used, in the precision
    // auto chose.
    const Scene sample = sample_bodies(scene, 64);
    Scene chosen = sample;
    chosen.precision = choice.precision;
    const Reference ref = reference_states(sample, duration, std::max<std::uint64_t>(64 * choice.steps, 4096));
    const BodyStates got = choice.step_tolerance
                               ? simulate_adaptive(chosen, *choice.method, *choice.step_tolerance, duration).states
                               : simulate(chosen, *choice.method, choice.steps, duration);
    CHECK(state_error(got, ref.states) <= tolerance);
    // Never more work than rk4: the fewest rk4 steps (by doubling) that meet the tolerance.
    std::uint64_t rk4_steps = 8;
    while (state_error(simulate(sample, rk4, rk4_steps, duration), ref.states) > tolerance) rk4_steps *= 2;
    CHECK(choice.evaluations <= 4.0 * double(rk4_steps));
  }
}

// The searches below run every explicit method's pilots at tens of thousands of steps: a
// minute and seven under the sanitizers, which the other auto tests cover.
#ifndef KINEMA_SANITIZED
namespace {

// Velocity Verlet's steps over `duration` at its largest stable step on the scene: the
// fewest force evaluations an explicit method can spend.
double verlet_evaluations(const Scene& scene, double duration) {
  const auto stiffness = estimate_stiffness(make_particles<double>(scene), make_forces<double>(scene));
  return duration / largest_stable_step(velocity_verlet, stiffness);
}

}  // namespace

TEST_CASE("auto takes an implicit method where a stiff spring sets every explicit step", "[accuracy][auto][implicit]") {
  // The shipped stiff pair: two bodies bound by a spring of k = 1e7 (their stretch mode at
  // 4472 rad/s, barely excited) swing together along it on soft, lightly damped anchor
  // springs (1 rad/s) for 10 s: every explicit method must step under 0.5 ms, the implicit
  // ones follow the swing.
  const Scene scene = load_scene(scene_path("stiff_pair"));
  const double tolerance = 1e-3, duration = 10;
  const MethodChoice choice = choose_method(scene, tolerance);
  INFO(choice.reason);
  REQUIRE(choice.method != nullptr);
  CHECK(choice.method->kind == MethodKind::linearly_implicit);
  CHECK_THAT(choice.reason, Catch::Contains("with their solves' iterations"));
  // Its cost counts its solves' iterations: a run of its steps takes these many.
  ParticleSet<double> bodies = make_particles<double>(scene);
  Stepper<double> stepper(make_forces<double>(scene), *choice.method, on_calling_thread());
  stepper.advance(bodies, duration / double(choice.steps), choice.steps);
  CHECK(choice.evaluations == double(choice.steps * choice.method->evaluations() + stepper.implicit_stats().iterations));
  const Reference ref = reference_states(scene, duration, std::uint64_t(1) << 18);
  CHECK(state_error(simulate(scene, *choice.method, choice.steps, duration), ref.states) <= tolerance);
  // Its solves counted, three times cheaper than any explicit method can be (one force
  // evaluation a step at velocity Verlet's largest stable step).
  CHECK(choice.evaluations < verlet_evaluations(scene, duration) / 3);
}

TEST_CASE("auto checks an implicit method's pilots against an explicit run", "[accuracy][auto][implicit]") {
  // A stiff spring (k = 1e8, its stretch mode at 14142 rad/s) turning with its bodies at
  // 2 rad/s: at steps far past its stretch mode each implicit step slows the turn, and
  // pilots at N, 2N and 4N steps, all slowed to a stop, agree with each other. Checked
  // against an explicit run, they are not taken.
  const Scene scene = parse_scene(R"({"precision": "double", "method": "rk4", "dt": 0.01, "steps": 1000,
    "particles": [{"position": [-0.5, 0, 0], "velocity": [0, -1, 0], "mass": 1},
                  {"position": [0.5, 0, 0], "velocity": [0, 1, 0], "mass": 1}],
    "forces": [{"type": "springs", "pairs": [[0, 1, 1, 1e8, 0.5]]}]})");
  const double tolerance = 1e-3, duration = 10;
  const MethodChoice choice = choose_method(scene, tolerance);
  INFO(choice.reason);
  REQUIRE(choice.method != nullptr);
  CHECK_THAT(choice.reason, Catch::Contains("ros2 misses the tolerance against"));
  const Reference ref = reference_states(scene, duration, std::uint64_t(1) << 18);
  CHECK(state_error(simulate(scene, *choice.method, choice.steps, duration), ref.states) <= tolerance);
}

TEST_CASE("auto says when a method's error estimate stops falling as its steps double", "[accuracy][auto]") {
  // The drag oscillator over 10 s in float: past a hundred thousand steps rk6's round-off
  // outgrows its truncation error, so its estimates rise as its steps double and it spends the
  // search. The refusal names that and what it means; in double the same tolerance is met.
  Scene scene = load_scene(scene_path("drag_oscillator"));
  scene.precision = Precision::single;
  try {
    choose_method(scene, 1e-6);
    FAIL("float met 1e-6");
  } catch (const Error& e) {
    CHECK_THAT(e.what(), Catch::Contains("rk6 did not settle (its error estimate") &&
                             Catch::Contains("at half as many) and spent the search budget"));
  }
  scene.precision = Precision::dual;
  const MethodChoice choice = choose_method(scene, 1e-6);
  REQUIRE(choice.method != nullptr);
  CHECK_THAT(choice.reason, !Catch::Contains("did not settle"));
}
#endif

TEST_CASE("auto passes over a candidate whose pilot fails and says so", "[accuracy][auto]") {
  // On the binary orbit at 1e-2 dopri5's error-controlled pilot cannot follow the close
  // approach (its step underflows); fixed steps still meet the tolerance.
  const MethodChoice choice = choose_method(load_scene(scene_path("binary_orbit")), 1e-2);
  CHECK(choice.method != nullptr);
  CHECK_THAT(choice.reason, Catch::Contains("with error control failed (advance_to: the step size underflows"));
  CHECK_FALSE(choice.step_tolerance);
}

TEST_CASE("auto keeps double where float cannot take the chosen error control", "[accuracy][auto]") {
  // At 1e-8 on the eccentric orbit dopri5 wins at rtol = atol = 1e-10, below float's round-off
  // on these bodies: the float check's own run is refused, and the choice stays in double.
  const Scene scene = load_scene(scene_path("kepler_eccentric"));
  REQUIRE(scene.precision == Precision::dual);
  const MethodChoice choice = choose_method(scene, 1e-8);
  REQUIRE(choice.method == &dopri5);
  REQUIRE(choice.step_tolerance);
  CHECK(*choice.step_tolerance == Approx(1e-10));
  CHECK(choice.precision == Precision::dual);
}

TEST_CASE("tighter tolerances take more steps", "[accuracy][auto]") {
  const Scene scene = load_scene(scene_path("damped_spring"));
  const MethodChoice loose = choose_method(scene, 1e-2), tight = choose_method(scene, 1e-9);
  CHECK(tight.method->order >= 4);
  CHECK(tight.evaluations > 4 * loose.evaluations);
  CHECK(loose.estimated_error <= 1e-2);
  CHECK(tight.estimated_error <= 1e-9);
  CHECK_THROWS_WITH(choose_method(scene, -1), "tolerance must be positive and finite");
}

namespace {

// A stop request that says stop at its `at`-th poll, and counts them.
struct StopAt {
  int at;
  std::shared_ptr<int> polls = std::make_shared<int>(0);
  bool operator()() const { return ++*polls >= at; }
};

}  // namespace

namespace {

// The shipped cluster's scene with fewer bodies (a coupled scene is not sampled).
Scene small_cluster(std::size_t count) {
  Scene scene = load_scene(scene_path("plummer_cluster"));
  scene.generate->count = count;
  scene.generate->mass = 1.0 / double(count);
  return scene;
}

}  // namespace

TEST_CASE("World::advance stops between calls on request, with the bits of one call", "[accuracy][stop]") {
  const Scene scene = small_cluster(1024);
  World<float> stopped(scene, rk4, test::serial_options()), whole(scene, rk4, test::serial_options());
  const std::uint64_t per_call = stopped.steps_per_call();
  REQUIRE(per_call >= 1);
  REQUIRE(per_call < 8);  // a step of 1024 bodies' pairs costs millions of interactions
  // Polled before each call and, N-body gravity taking long, before each block (one) of each
  // of rk4's four passes: a call of p steps makes 1 + 4p polls.
  const int per_call_polls = 1 + 4 * int(per_call);
  CHECK(World<float>(scene, rk4, test::serial_options()).advance(1e-3f, 40, StopAt{3 * per_call_polls + 1}) ==
        3 * per_call);
  // Inside the third call's last step: that step is not taken.
  const std::uint64_t done = stopped.advance(1e-3f, 40, StopAt{3 * per_call_polls});
  CHECK(done == 3 * per_call - 1);
  whole.advance(1e-3f, done);
  CHECK(test::state_hash(stopped.particles) == test::state_hash(whole.particles));
  CHECK(stopped.time() == whole.time());
  CHECK(stopped.advance(1e-3f, 5, {}) == 5);
}

TEST_CASE("the long analyses throw Stopped once their stop request says so", "[accuracy][stop]") {
  const Scene orbit = load_scene(scene_path("binary_orbit"));
  const Scene cluster = small_cluster(256);
  const StopAt third{3};
  CHECK_THROWS_AS(simulate(cluster, rk4, 4000, 1.0, third), Stopped);
  CHECK(*third.polls == 3);
  CHECK_THROWS_AS(reference_states(cluster, 1.0, 4000, StopAt{2}), Stopped);
  CHECK_THROWS_AS(simulate_adaptive(orbit, dopri5, 1e-10, 10.0, 1.0, StopAt{50}), Stopped);
  // A stopped pilot ends the search, not the one method: no choice is made.
  CHECK_THROWS_AS(choose_method(orbit, 1e-6, StopAt{20}), Stopped);
  const ParticleSet<double> bodies = make_particles<double>(cluster);
  const StopAt tenth{10};
  CHECK_THROWS_AS(estimate_stiffness(bodies, make_forces<double>(cluster), 0, 40, on_calling_thread(), tenth), Stopped);
  CHECK(*tenth.polls == 10);  // polled before each force evaluation
  // Never asked to stop: the results of the calls without a request.
  const BodyStates a = simulate(cluster, rk4, 20, 0.1, [] { return false; }), b = simulate(cluster, rk4, 20, 0.1);
  CHECK(state_error(a, b) == 0);
}
