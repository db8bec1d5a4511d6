// Scene parsing: the documented contract, defaults, generation, and errors with JSON paths.
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>

#include "support.hpp"

using namespace kinema;

TEST_CASE("the documented scene format parses as written", "[scene]") {
  const Scene s = parse_scene(R"({
    "name": "orbit", "precision": "double", "method": "rk4", "dt": 0.01, "steps": 1000,
    "particles": [ {"position": [1,0,0], "velocity": [0,1,0], "mass": 1} ],
    "generate": {"count": 1000, "seed": 7, "position_min": [-1,-1,-1], "position_max": [1,1,1],
                 "velocity_min": [0,0,0], "velocity_max": [0,0,0], "mass": 1},
    "forces": [ {"type": "gravity", "g": [0,-9.81,0]}, {"type": "linear_drag", "k": 0.1},
                {"type": "quadratic_drag", "k": 0.01},
                {"type": "spring", "anchor": [0,0,0], "k": 4, "damping": 0},
                {"type": "central", "center": [0,0,0], "mu": 1} ] })");
  CHECK(s.name == "orbit");
  CHECK(s.precision == Precision::dual);
  CHECK(s.method == "rk4");
  CHECK(s.dt == 0.01);
  CHECK(s.steps == 1000);
  REQUIRE(s.particles.size() == 1);
  CHECK(s.particles[0].velocity == Vec3<double>{0, 1, 0});
  REQUIRE(s.forces.size() == 5);
  CHECK(std::get<Spring>(s.forces[3]).k == 4);
  CHECK(std::get<Central>(s.forces[4]).mu == 1);
  const ParticleSet<double> b = make_particles<double>(s);
  REQUIRE(b.size() == 1001);
  CHECK(b.position(0) == Vec3<double>{1, 0, 0});  // listed bodies first
  for (std::size_t i = 1; i < b.size(); ++i) {
    for (double c : b.position(i)) REQUIRE((c >= -1 && c <= 1));
    REQUIRE(b.velocity(i) == Vec3<double>{0, 0, 0});
  }
  CHECK(make_forces<double>(s).local_terms().size() == 5);
}

TEST_CASE("generation is reproducible from the seed and changes with it", "[scene]") {
  Scene s;
  s.generate = GenerateSpec{500, 42, {-5, 0, 0}, {5, 1, 2}, {-1, -1, -1}, {1, 1, 1}, 3};
  const auto a = make_particles<float>(s), b = make_particles<float>(s);
  CHECK(test::state_hash(a) == test::state_hash(b));
  s.generate->seed = 43;
  CHECK(test::state_hash(make_particles<float>(s)) != test::state_hash(a));
  // Bodies spread over the whole box: the sample mean of x is near its centre.
  double mean = 0;
  for (std::size_t i = 0; i < a.size(); ++i) mean += a.position(i)[0] / double(a.size());
  CHECK(std::abs(mean) < 0.5);
}

TEST_CASE("defaults: float, rk4, optional velocity and mass", "[scene]") {
  const Scene s = parse_scene(R"({"particles": [{"position": [0, 1, 2]}]})");
  CHECK(s.precision == Precision::single);
  CHECK(s.method == "rk4");
  CHECK(s.particles[0].mass == 1);
  CHECK(s.particles[0].velocity == Vec3<double>{0, 0, 0});
}

TEST_CASE("scene errors name the JSON path", "[scene][errors]") {
  const std::pair<const char*, const char*> cases[] = {
      {R"({"particles": [{"position": [0,0,0]}], "forces": [{"type": "gravity", "g": [0,0,0]},
          {"type": "linear_drag", "k": 1}, {"type": "spring", "k": "stiff"}]})",
       "scene: forces[2].k: expected a number"},
      {R"({"particles": [{"position": [0,0]}]})",
       "scene: particles[0].position: expected an array of 3 numbers"},
      {R"({"particles": [{"position": [0,0,0], "mass": -2}]})",
       "scene: particles[0].mass: expected a number > 0"},
      {R"({"particles": [{"position": [0,0,0]}], "forces": [{"type": "magnet"}]})",
       "scene: forces[0].type: unknown force 'magnet'"},
      {R"({"particles": [{"position": [0,0,0]}], "forces": [{"type": "spring", "k": 1, "damp": 1}]})",
       "scene: forces[0].damp: unknown key"},
      {R"({"particles": [{"position": [0,0,0]}], "dt": 0})", "scene: dt: expected a number > 0"},
      {R"({"particles": [{"position": [0,0,0]}], "precision": "half"})",
       "scene: precision: expected \"float\" or \"double\""},
      {R"({"generate": {"count": 10, "position_min": [0,0,0], "position_max": [1,-1,1]}})",
       "scene: generate.position_max: must not be below position_min"},
      {R"({"particles": []})", "scene: (top level): the scene has no bodies"},
      {R"({"particles": [{"position": [0,0,0]}], "steps": 1.5})",
       "scene: steps: expected an integer >= 0"},
      {R"({"particles": [{"position": [0,0,0]}],)", "scene: invalid JSON"},
  };
  for (const auto& [text, message] : cases) {
    INFO(text);
    CHECK_THROWS_WITH(parse_scene(text), Catch::StartsWith(message));
  }
}

TEST_CASE("a force that fails in the model names its index", "[scene][errors]") {
  Scene s;
  s.particles.push_back({});
  s.forces = {Gravity{}, LinearDrag{-3}};
  CHECK_THROWS_WITH(make_forces<float>(s), "forces[1]: linear_drag.k: must be finite and >= 0");
}

TEST_CASE("every shipped scene loads", "[scene]") {
  for (const char* name : {"kepler_circular", "kepler_eccentric", "damped_spring", "projectiles",
                           "drag_field"}) {
    INFO(name);
    const Scene s = load_scene(std::string(KINEMA_SCENES) + "/" + name + ".json");
    CHECK(s.name == name);
    CHECK_NOTHROW(method_by_name(s.method));
  }
}

TEST_CASE("rigid bodies in scenes: angular velocity, full inertia tensors, generation", "[scene][rigid]") {
  const Scene s = parse_scene(R"({
    "rigid_bodies": [
      {"position": [1, 2, 3], "angular_velocity": [0, 0, 2], "mass": 2, "inertia": [1, 2, 4]},
      {"position": [0, 0, 0], "orientation": [0, 0, 0, 2], "angular_momentum": [1, 0, 0],
       "inertia": [[2, 1, 0], [1, 2, 0], [0, 0, 3]]}],
    "generate": {"kind": "rigid", "count": 50, "position_min": [0,0,0], "position_max": [1,1,1],
                 "inertia": [1, 1, 1], "angular_velocity_min": [-1,-1,-1],
                 "angular_velocity_max": [1,1,1]} })");
  REQUIRE(s.rigid_bodies.size() == 2);
  CHECK(s.rigid_bodies[0].angular_momentum == Vec3<double>{0, 0, 8});  // I_z omega
  // [[2,1,0],[1,2,0],[0,0,3]] has principal moments 1, 3, 3.
  std::vector<double> m(s.rigid_bodies[1].inertia.begin(), s.rigid_bodies[1].inertia.end());
  std::sort(m.begin(), m.end());
  CHECK(m[0] == Approx(1));
  CHECK(m[1] == Approx(3));
  CHECK(m[2] == Approx(3));
  const RigidBodySet<double> b = make_rigid_bodies<double>(s);
  REQUIRE(b.size() == 52);
  CHECK(make_particles<double>(s).size() == 0);  // generated bodies are rigid here
  CHECK(b.angular_velocity(0)[2] == Approx(2));
  for (std::size_t i = 2; i < b.size(); ++i) {
    const auto omega = b.angular_velocity(i);
    for (double w : omega) REQUIRE(std::abs(w) <= 1 + 1e-12);
    const auto q = b.orientation(i);
    REQUIRE(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] == Approx(1));
  }
}

TEST_CASE("rigid body scene errors name the JSON path", "[scene][rigid][errors]") {
  const std::pair<const char*, const char*> cases[] = {
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[1,0,0],[0,-1,0],[0,0,1]]}]})",
       "scene: rigid_bodies[0].inertia: the tensor is not positive definite"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [1, 0, 1]}]})",
       "scene: rigid_bodies[0].inertia[1]: expected a number > 0"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "orientation": [0,0,0,0]}]})",
       "scene: rigid_bodies[0].orientation: the quaternion is zero"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "angular_velocity": [1,0,0], "angular_momentum": [1,0,0]}]})",
       "scene: rigid_bodies[0].angular_momentum: give angular_velocity or angular_momentum"},
      {R"({"generate": {"count": 3, "position_min": [0,0,0], "position_max": [1,1,1], "inertia": [1,1,1]}})",
       "scene: generate.inertia: only for \"kind\": \"rigid\""},
      {R"({"rigid_bodies": [{"position": [0,0,0]}], "forces": [{"type": "torque", "torque": [1, 0]}]})",
       "scene: forces[0].torque: expected an array of 3 numbers"},
  };
  for (const auto& [text, message] : cases) {
    INFO(text);
    CHECK_THROWS_WITH(parse_scene(text), Catch::StartsWith(message));
  }
}

TEST_CASE("coupled terms in scenes: nbody, spring pairs, chain and grid generators", "[scene][springs]") {
  const Scene s = parse_scene(R"({"particles": [{"position": [0,0,0]}, {"position": [1,0,0]}],
      "forces": [{"type": "nbody", "G": 2, "softening": 0.5, "fast": true},
                 {"type": "springs", "pairs": [[0, 1, 1.5, 10, 0.25]]},
                 {"type": "springs", "chain": {"count": 3, "spacing": 0.5, "k": 4, "direction": [2, 0, 0]}},
                 {"type": "springs", "grid": {"rows": 2, "columns": 3, "spacing": 1, "k": 7, "shear_k": 5,
                                              "mass": 2, "origin": [0, 9, 0], "pinned": "top_corners"}}]})");
  REQUIRE(s.nbody);
  CHECK(s.nbody->G == 2);
  CHECK(s.nbody->softening == 0.5);
  CHECK(s.nbody->fast);
  REQUIRE(s.springs.size() == 3);
  CHECK(s.springs[0].pairs[0].rest == 1.5);
  CHECK(s.springs[0].pairs[0].damping == 0.25);
  // The chain's 3 bodies follow the 2 listed ones along +x; its first is pinned.
  REQUIRE(s.particles.size() == 2 + 3 + 6);
  CHECK(s.particles[2].kinematic);
  CHECK(s.particles[4].position == Vec3<double>{1, 0, 0});
  CHECK(s.springs[1].pairs.size() == 2);
  CHECK(s.springs[1].pairs[1].i == 3);
  CHECK(s.springs[1].pairs[1].j == 4);
  // A 2 x 3 grid: 4 springs along rows, 3 across, 2 x 2 shear springs; the top corners pinned.
  CHECK(s.springs[2].pairs.size() == 4 + 3 + 4);
  CHECK(s.particles[5].kinematic);
  CHECK(s.particles[7].kinematic);
  CHECK_FALSE(s.particles[6].kinematic);
  CHECK(s.particles[10].position == Vec3<double>{2, 9, 1});
  CHECK(s.particles[10].mass == 2);
  const ForceModel<double> f = make_forces<double>(s);
  CHECK(f.springs().size() == 1 + 2 + 11);
  CHECK_FALSE(f.fusable());
}

TEST_CASE("coupled term errors name the JSON path", "[scene][springs][errors]") {
  const std::string two = R"({"particles": [{"position": [0,0,0]}, {"position": [1,0,0]}], "forces": [)";
  const std::pair<std::string, const char*> cases[] = {
      {two + R"({"type": "springs", "pairs": [[0, 1, 1, 1, 0], [0, 7, 1, 1, 0]]}]})",
       "scene: forces[0].pairs[1]: joins body 7, but the scene has 2 particles"},
      {two + R"({"type": "springs", "pairs": [[0, 1, 1, 1, 0], [1, 0, 2, 1, 0]]}]})",
       "scene: forces[0].pairs[1]: repeats forces[0].pairs[0] (bodies 0 and 1)"},
      {two + R"({"type": "springs", "pairs": [[1, 1, 1, 1, 0]]}]})",
       "scene: forces[0].pairs[0]: joins body 1 to itself"},
      {two + R"({"type": "springs", "pairs": [[0, 1, -1, 1, 0]]}]})",
       "scene: forces[0].pairs[0][2]: expected a number >= 0"},
      {two + R"({"type": "springs", "pairs": [[0, -1, 1, 1, 0]]}]})",
       "scene: forces[0].pairs[0][1]: expected an integer >= 0"},
      {two + R"({"type": "springs", "pairs": [[0, 1, 1, 1]]}]})",
       "scene: forces[0].pairs[0]: expected [i, j, rest, k, damping]"},
      {two + R"({"type": "springs"}]})", "scene: forces[0]: expected one of 'pairs', 'chain' or 'grid'"},
      {two + R"({"type": "springs", "grid": {"rows": 0, "columns": 2, "spacing": 1, "k": 1}}]})",
       "scene: forces[0].grid.rows: expected an integer >= 1"},
      {two + R"({"type": "springs", "grid": {"rows": 2048, "columns": 1024, "spacing": 1, "k": 1}}]})",
       "scene: forces[0].grid: expected at most 2^20 bodies (rows x columns)"},
      {two + R"({"type": "springs", "chain": {"count": 3, "spacing": 1, "k": 1, "pinned": [3]}}]})",
       "scene: forces[0].chain.pinned[0]: expected an index below 3"},
      {two + R"({"type": "springs", "chain": {"count": 3, "spacing": 1, "k": 1, "pinned": [0, 0]}}]})",
       "scene: forces[0].chain.pinned[1]: body 0 is pinned twice"},
      {two + R"({"type": "springs", "chain": {"count": 3, "spacing": 1, "k": 1, "direction": [0, 0, 0]}}]})",
       "scene: forces[0].chain.direction: expected a nonzero direction"},
      {two + R"({"type": "nbody", "G": -1}]})", "scene: forces[0].G: expected a number >= 0"},
      {two + R"({"type": "nbody", "fast": 1}]})", "scene: forces[0].fast: expected true or false"},
      {two + R"({"type": "nbody"}, {"type": "nbody"}]})", "scene: forces[1]: at most one nbody term"},
      {R"({"rigid_bodies": [{"position": [0,0,0]}], "particles": [{"position": [0,0,0]}], "forces": [{"type": "nbody"}]})",
       "scene: forces[0]: nbody acts among bodies of one kind; the scene has particles and rigid bodies"},
      {two + R"({"type": "body_springs", "springs": [{"i": 0, "j": 1, "k": 1}]}]})",
       "scene: forces[0].springs[0]: joins body 1, but the scene has 0 rigid bodies"},
      {R"({"rigid_bodies": [{"position": [0,0,0]}], "particles": [{"position": [0,0,0]}], "events": [{"type": "plane"}]})",
       "scene: events: events watch bodies of one kind; the scene has particles and rigid bodies"},
      {R"({"rigid_bodies": [{"position": [0,0,0]}], "events": [{"type": "plane"}],
           "forces": [{"type": "point_spring", "point": [0.1,0,0], "anchor": [0,1,0], "k": 2}]})",
       "scene: events: events on rigid bodies are watched with local terms only: not with body_springs or point_spring"},
      {R"({"generate": {"count": 4, "distribution": "plummer"}})", "scene: generate: missing key 'radius'"},
      {R"({"generate": {"count": 4, "distribution": "plummer", "radius": 1, "position_min": [0,0,0]}})",
       "scene: generate.position_min: only for \"distribution\": \"box\""},
  };
  for (const auto& [text, message] : cases) {
    INFO(text);
    CHECK_THROWS_WITH(parse_scene(text), Catch::StartsWith(message));
  }
}

TEST_CASE("the implicit methods take scenes of particles with springs, without rigid bodies or events", "[scene][implicit]") {
  const Scene chain = parse_scene(R"({"forces": [{"type": "springs", "chain": {"count": 3, "spacing": 1, "k": 1}}]})");
  CHECK(takes_implicit_methods(chain));
  CHECK_FALSE(takes_implicit_methods(parse_scene(R"({"particles": [{"position": [0,0,0]}]})")));
  // Scenes refuse these mixes; a Scene made in code may hold them.
  Scene with_rigid = chain, generated_rigid = chain, watched = chain;
  with_rigid.rigid_bodies.emplace_back();
  generated_rigid.generate = GenerateSpec{};
  generated_rigid.generate->rigid = true;
  watched.events.emplace_back();
  CHECK_FALSE(takes_implicit_methods(with_rigid));
  CHECK_FALSE(takes_implicit_methods(generated_rigid));
  CHECK_FALSE(takes_implicit_methods(watched));
}

TEST_CASE("a scene made in code with both body kinds and events is refused as a file of them is", "[scene][events]") {
  Scene both = parse_scene(R"({"particles": [{"position": [0, 1, 0]}], "rigid_bodies": [{"position": [0, 1, 0]}],
      "forces": [{"type": "gravity", "g": [0, -9.81, 0]}]})");
  both.events.push_back(EventSpec{PlaneEvent{{0, 1, 0}, 0}});
  CHECK_THROWS_WITH(check_scene<float>(both), "events: events watch bodies of one kind; the scene has particles and rigid bodies");
  World<float> world(both, rk4);
  CHECK_THROWS_WITH(world.watch_events(), Catch::Contains("this world has particles and rigid bodies"));
  both.particles.clear();  // one kind: watched, the rigid body's crossing found
  World<float> rigid(both, rk4);
  rigid.watch_events();
  rigid.advance(0.01f, 100);
  CHECK(rigid.event_hits().size() == 1);
}

TEST_CASE("an empty world's clock goes on under every advance", "[scene]") {
  World<double> world(Scene{}, rk4);  // a level with no bodies yet
  world.advance(0.01, 10);
  CHECK(world.time() == Approx(0.1));
  CHECK(world.advance(0.01, 10, [] { return false; }) == 10);
  CHECK(world.time() == Approx(0.2));
  World<double> adaptive(Scene{}, dopri5);
  adaptive.advance(0.01, 10);
  adaptive.advance_to(0.5, {1e-6, 1e-6});
  CHECK(adaptive.time() == 0.5);
}

TEST_CASE("a kind of body the world ran out of keeps the world's clock for bodies added later", "[scene]") {
  const Scene both = parse_scene(R"({"particles": [{"position": [0, 1, 0]}], "rigid_bodies": [{"position": [0, 1, 0]}],
      "forces": [{"type": "gravity", "g": [0, -9.81, 0]}]})");
  World<float> world(both, rk4);
  world.advance(0.01f, 5);
  world.particles.remove(0);  // the rigid body goes on alone
  world.advance(0.01f, 5);
  CHECK(world.advance(0.01f, 5, [] { return false; }) == 5);
  world.particles.add({0, 1, 0}, {}, 1);
  world.advance(0.01f, 5);
  CHECK(world.particle_stepper().clock().steps == 20);
  CHECK(world.rigid_stepper().clock().steps == 20);
  CHECK(world.particle_stepper().time() == world.rigid_stepper().time());
  CHECK(world.time() == Approx(0.2));
  world.rigid.remove(0);  // and the other way
  world.advance(0.01f, 3);
  world.rigid.add({{0, 1, 0}, {}, {1, 0, 0, 0}, {}, 1, {1, 1, 1}});
  world.advance(0.01f, 1);
  CHECK(world.rigid_stepper().clock().steps == 24);
  CHECK(world.rigid_stepper().time() == world.particle_stepper().time());
  // A call that throws after steps were taken: the steps completed count for both clocks.
  // Euler on v' = -30 v with h = 0.1 doubles |v| each step: in float the guard stops at step 128.
  StepperOptions guarded;
  guarded.guard = FiniteGuard::check;
  World<float> spiral(parse_scene(R"({"particles": [{"position": [1, 0, 0], "velocity": [1, 0, 0]}],
      "forces": [{"type": "linear_drag", "k": 30}]})"), euler, guarded);
  CHECK_THROWS_AS(spiral.advance(0.1f, 1000), NonFiniteError);
  CHECK(spiral.particle_stepper().clock().steps == 127);
  CHECK(spiral.rigid_stepper().clock().steps == 127);
}

TEST_CASE("a dynamic body at an attractor's centre is refused where it is listed", "[scene][errors]") {
  const std::string central = R"("forces": [{"type": "central", "center": [0, 1, 0], "mu": 2}]})";
  CHECK_THROWS_WITH(parse_scene(R"({"particles": [{"position": [1,0,0]}, {"position": [0,1,0]}], )" + central),
                    "scene: particles[1]: sits at the centre of a central term (mu / r^2 is infinite there)");
  CHECK_THROWS_WITH(parse_scene(R"({"rigid_bodies": [{"position": [0,1,0]}], )" + central),
                    Catch::StartsWith("scene: rigid_bodies[0]: sits at the centre"));
  // A body a spring network makes there is named by its network.
  CHECK_THROWS_WITH(parse_scene(R"({"forces": [{"type": "central", "center": [0, 0, 0], "mu": 1},
      {"type": "springs", "grid": {"rows": 2, "columns": 2, "spacing": 1, "k": 1}}]})"),
                    "scene: forces[1].grid: its body 0 sits at the centre of a central term (mu / r^2 is infinite there)");
  // A kinematic body there (a sun the attractor stands for) is moved by no force.
  CHECK(parse_scene(R"({"particles": [{"position": [0,1,0], "kinematic": true}], )" + central).particles.size() == 1);
}

TEST_CASE("rigid bodies in scenes: body springs, point springs, kinematic anchors, coupled terms", "[scene][rigid][springs]") {
  const Scene s = parse_scene(R"({"rigid_bodies": [{"position": [0,0,0], "kinematic": true}, {"position": [0,-1,0]},
                                                   {"position": [0,-2,0]}],
    "forces": [{"type": "point_spring", "point": [0, 1, 0], "anchor": [0, 5, 0], "k": 3},
               {"type": "body_springs", "springs": [{"i": 0, "j": 1, "point_j": [0, 0.5, 0], "rest": 0.5, "k": 100, "damping": 2}]},
               {"type": "body_springs", "springs": [{"i": 1, "j": 2, "point_i": [0.1, 0, 0], "point_j": [0, 0.5, 0], "k": 50}]},
               {"type": "springs", "pairs": [[0, 2, 2, 10, 0]]},
               {"type": "nbody", "G": 0.5}]})");
  REQUIRE(s.body_springs.springs.size() == 2);
  const BodySpring& b = s.body_springs.springs[1];
  CHECK((b.i == 1 && b.j == 2 && b.point_i == Vec3<double>{0.1, 0, 0} && b.point_j == Vec3<double>{0, 0.5, 0}));
  CHECK((b.rest == 0 && b.k == 50 && b.damping == 0));
  CHECK(s.body_springs.springs[0].damping == 2);
  const ForceModel<double> f = make_forces<double>(s);
  CHECK(f.body_springs().size() == 2);
  CHECK(f.springs().size() == 1);
  CHECK(f.nbody());
  CHECK(std::holds_alternative<PointSpring>(f.local_terms()[0]));
  const RigidBodySet<double> r = make_rigid_bodies<double>(s);
  CHECK(r.centers().inv_mass()[0] == 0);
  CHECK(r.centers().inv_mass()[1] == 1);
  // Built into a world, they step: the anchor stays where it is.
  World<double> w(s, rk4, on_calling_thread());
  w.advance(0.01, 10);
  CHECK(w.rigid.centers().position(0) == Vec3<double>{0, 0, 0});
  CHECK(w.rigid.centers().position(1)[1] != -1);
  CHECK_THROWS_WITH(parse_scene(R"({"rigid_bodies": [{"position": [0,0,0], "kinematic": true, "force": [1,0,0]}]})"),
                    Catch::Contains("rigid_bodies[0].force: a kinematic body ignores forces"));
  CHECK_THROWS_WITH(parse_scene(R"({"rigid_bodies": [{"position": [0,0,0]}, {"position": [1,0,0]}],
    "forces": [{"type": "body_springs", "springs": [{"i": 0, "j": 1, "k": 1}, {"i": 1, "j": 1, "k": 1}]}]})"),
                    Catch::StartsWith("scene: forces[0].springs[1]: joins body 1 to itself"));
  CHECK_THROWS_WITH(parse_scene(R"({"rigid_bodies": [{"position": [0,0,0]}, {"position": [1,0,0]}],
    "forces": [{"type": "springs", "pairs": [[0, 2, 1, 1, 0]]}]})"),
                    Catch::StartsWith("scene: forces[0].pairs[0]: joins body 2, but the scene has 2 rigid bodies"));
  CHECK_THROWS_WITH(parse_scene(R"({"rigid_bodies": [{"position": [0,0,0]}], "forces": [{"type": "springs", "chain": {"count": 3, "spacing": 1, "k": 1}}]})"),
                    Catch::StartsWith("scene: forces[0]: springs join bodies of one kind; the scene has particles and rigid bodies"));
}

TEST_CASE("a Plummer sphere is centred, at rest, and near virial equilibrium", "[scene]") {
  Scene s = parse_scene(R"({"generate": {"count": 2000, "distribution": "plummer", "radius": 1, "mass": 0.0005},
                            "forces": [{"type": "nbody", "G": 1}]})");
  const ParticleSet<double> b = make_particles<double>(s);
  const ForceModel<double> f = make_forces<double>(s);
  const Vec3<double> p = momentum(b);
  CHECK(std::hypot(p[0], p[1], p[2]) < 1e-12);
  Vec3<double> centre{};
  for (std::size_t i = 0; i < b.size(); ++i) {
    for (int d = 0; d < 3; ++d) centre[d] += b.position(i)[d] / double(b.size());
  }
  CHECK(std::hypot(centre[0], centre[1], centre[2]) < 1e-12);
  // 2T + U = 0 in equilibrium; the total energy of a Plummer sphere is -3 pi G M^2 / (64 a).
  const double kinetic = kinetic_energy(b), potential = potential_energy(b, f);
  CHECK(2 * kinetic / -potential == Approx(1).margin(0.1));
  CHECK(kinetic + potential == Approx(-3 * std::numbers::pi / 64).epsilon(0.1));
}

TEST_CASE("a scene's bodies may carry constant applied forces and torques", "[scene][applied]") {
  const Scene s = parse_scene(R"({
    "precision": "double",
    "particles": [{"position": [0, 0, 0], "mass": 2, "force": [0, 19.62, 4]},
                  {"position": [1, 0, 0]}],
    "rigid_bodies": [{"position": [0, 0, 0], "mass": 2, "inertia": [0.5, 0.5, 0.5],
                      "force": [2, 0, 0], "torque": [0, 0, 1.5]}],
    "forces": [{"type": "gravity", "g": [0, -9.81, 0]}]
  })");
  ParticleSet<double> p = make_particles<double>(s);
  Stepper<double> stepper(make_forces<double>(s), rk4, on_calling_thread());
  stepper.advance(p, 0.01, 10);
  stepper.advance(p, 0.01, 10);  // a scene's forces act for the whole run
  CHECK(p.velocity(0)[1] == Approx(0).margin(1e-13));  // held up against gravity
  CHECK(p.velocity(0)[2] == Approx(2 * 0.2).epsilon(1e-13));
  CHECK(p.velocity(1)[1] == Approx(-9.81 * 0.2).epsilon(1e-13));
  CHECK_FALSE(p.applied_force_data(0) == nullptr);

  RigidBodySet<double> r = make_rigid_bodies<double>(s);
  Stepper<double>(ForceModel<double>{}, rk4, on_calling_thread()).advance(r, 0.01, 20);
  CHECK(r.centers().velocity(0)[0] == Approx(0.2).epsilon(1e-13));
  CHECK(r.angular_momentum(0)[2] == Approx(1.5 * 0.2).epsilon(1e-13));

  // The closed-form reference knows the applied force.
  Scene particles_only = s;
  particles_only.rigid_bodies.clear();
  const auto exact = analytic_states(particles_only, 0.2);
  REQUIRE(exact);
  CHECK(exact->velocities[0][2] == Approx(p.velocity(0)[2]).epsilon(1e-12));
  CHECK(exact->positions[0][1] == Approx(p.position(0)[1]).margin(1e-12));
}

TEST_CASE("a scene's bodies may carry a gravity factor and damping rates", "[scene][parameters]") {
  const Scene s = parse_scene(R"({
    "precision": "double",
    "particles": [{"position": [0, 0, 0], "velocity": [1, 0, 0], "gravity_factor": 0.5, "damping": 0.8},
                  {"position": [1, 0, 0]}],
    "rigid_bodies": [{"position": [0, 0, 0], "angular_momentum": [0, 0, 2], "inertia": [0.5, 0.5, 0.5],
                      "angular_damping": 1.5, "gravity_factor": 0}],
    "forces": [{"type": "gravity", "g": [0, -9.81, 0]}]
  })");
  ParticleSet<double> p = make_particles<double>(s);
  CHECK(p.gravity_factor(0) == 0.5);
  CHECK(p.linear_damping(0) == 0.8);
  CHECK(p.gravity_factor(1) == 1);
  Stepper<double>(make_forces<double>(s), rk4, on_calling_thread()).advance(p, 0.01, 20);
  RigidBodySet<double> r = make_rigid_bodies<double>(s);
  CHECK(r.parameters().data(BodyParameter::linear_damping) == nullptr);  // only what the scene set
  Stepper<double>(make_forces<double>(s), rk4, on_calling_thread()).advance(r, 0.01, 20);
  CHECK(r.angular_momentum(0)[2] == Approx(2 * std::exp(-1.5 * 0.2)).epsilon(1e-8));  // rk4 at h = 0.01
  CHECK(r.centers().velocity(0)[1] == 0);  // gravity factor 0

  // The closed-form reference knows them.
  Scene particles_only = s;
  particles_only.rigid_bodies.clear();
  const auto exact = analytic_states(particles_only, 0.2);
  REQUIRE(exact);
  for (std::size_t i : {0u, 1u}) {
    for (int d = 0; d < 3; ++d) {
      CHECK(exact->velocities[i][d] == Approx(p.velocity(i)[d]).margin(1e-10));
      CHECK(exact->positions[i][d] == Approx(p.position(i)[d]).margin(1e-10));
    }
  }
}

TEST_CASE("per-body parameters in scenes are checked", "[scene][parameters][errors]") {
  CHECK_THROWS_WITH(parse_scene(R"({"particles": [{"position": [0, 0, 0], "damping": -1}]})"),
                    Catch::Contains("particles[0].damping"));
  CHECK_THROWS_WITH(parse_scene(R"({"rigid_bodies": [{"position": [0, 0, 0], "angular_damping": "a"}]})"),
                    Catch::Contains("rigid_bodies[0].angular_damping"));
  const Scene big = parse_scene(R"({"particles": [{"position": [0, 0, 0], "gravity_factor": 1e39}]})");
  CHECK_THROWS_WITH(make_particles<float>(big), Catch::Contains("particles[0]") && Catch::Contains("gravity factor"));
}

TEST_CASE("applied forces in scenes are checked", "[scene][applied][errors]") {
  CHECK_THROWS_WITH(parse_scene(R"({"particles": [{"position": [0, 0, 0], "kinematic": true, "force": [1, 0, 0]}]})"),
                    Catch::Contains("particles[0].force") && Catch::Contains("kinematic"));
  CHECK_THROWS_WITH(parse_scene(R"({"particles": [{"position": [0, 0, 0], "force": [1, "a", 0]}]})"),
                    Catch::Contains("particles[0].force"));
  const Scene big = parse_scene(R"({"particles": [{"position": [0, 0, 0], "force": [1e39, 0, 0]}]})");
  CHECK_THROWS_WITH(make_particles<float>(big), Catch::Contains("particles[0]") && Catch::Contains("force"));
}
