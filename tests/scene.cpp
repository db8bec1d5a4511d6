// Scene parsing: the documented contract, defaults, generation, and errors with JSON paths.
#include <catch2/catch.hpp>

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
