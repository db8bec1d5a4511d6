// Hostile and careless input to the kinema program: every case ends with the exit code it
// should, one line on stderr that names the problem (control characters escaped), and
// nothing run that the input did not ask for. Table first, then the cases that need more
// than an exit code and a message: signals, write errors, chart injection, blow-ups.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdlib>
#include <map>
#include <sstream>

#include <sys/stat.h>
#include <sys/wait.h>

#include <nlohmann/json.hpp>

#include "cli_support.hpp"
#include "kinema/job_system.hpp"

using namespace kinema::test;

namespace {

const std::string kScenes = KINEMA_SCENES;
const std::string kSpring = kScenes + "/damped_spring.json";

// A scene body that is valid on its own, to splice the hostile part into.
const std::string P = R"("particles": [{"position": [1,0,0]}])";
std::string with_body(const std::string& rest) { return "{" + P + ", " + rest + "}"; }
std::string force(const std::string& term) { return with_body(R"("forces": [)" + term + "]"); }
std::string generated(const std::string& rest) {
  return R"({"generate": {"count": 8388608, "position_min": [0,0,0], "position_max": [1,1,1]}, )" +
         rest + "}";
}

struct Case {
  std::string scene;              // written to a file that "{}" in args stands for; "" for none
  std::vector<std::string> args;  // after "kinema"
  int code;                       // the exit code wanted
  std::string message;            // a piece of the one stderr line ("" when it must be silent)
  long peak_mib = 0;              // when set: peak memory above `kinema --help` must stay below
};

// Control characters other than the final newline.
bool has_raw_control(const std::string& s) {
  for (std::size_t i = 0; i + 1 < s.size(); ++i) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c < 0x20 || c == 0x7F) return true;
  }
  return false;
}

std::vector<std::string> run_args(std::vector<std::string> extra = {}) {
  std::vector<std::string> a{"run", "{}", "-q"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

std::vector<Case> scene_cases() {
  const std::string nul_then_garbage = std::string("{") + P + "}" + std::string(1, '\0') + "garbage";
  std::string deep = R"({"name": )";
  for (int i = 0; i < 20000; ++i) deep += "[";
  for (int i = 0; i < 20000; ++i) deep += "]";
  deep += ", " + P + "}";
  return {
      // JSON as text: syntax, numbers out of range, duplicate keys, bytes that end parsing.
      {"{\"particles\": [", run_args(), 1, "particles[0]: invalid JSON: parse error at line 1, column 16: syntax error while parsing value"},
      {"", {"run", (work_dir() / "missing.json").string()}, 1, "cannot open the file (No such file or directory)"},
      {"", {"run", write("empty.json", "").string()}, 1, "invalid JSON"},
      {" ", run_args(), 1, "invalid JSON"},
      {"[1, 2, 3]", run_args(), 1, "(top level): expected an object"},
      {"{" + P + "} trailing", run_args(), 1, "invalid JSON"},
      {nul_then_garbage, run_args(), 1, "a NUL byte at offset"},
      {with_body("\"dt\": 1e400"), run_args(), 1, "dt: invalid JSON"},
      {with_body("\"dt\": -1e400"), run_args(), 1, "dt: invalid JSON"},
      {R"({"particles": [{"position": [1,0,0]}, {"position": [1,0,1e999]}]})", run_args(), 1,
       "particles[1].position[2]: invalid JSON"},
      {with_body("\"dt\": 0.1, \"dt\": 0.2"), run_args(), 1, "dt: duplicate key"},
      {R"({"particles": [{"position": [1,0,0], "position": [2,0,0]}]})", run_args(), 1,
       "particles[0].position: duplicate key"},
      {R"({"generate": {"count": 1, "count": 2, "position_min": [0,0,0], "position_max": [1,1,1]}})",
       run_args(), 1, "generate.count: duplicate key"},
      {deep, run_args(), 1, "nested deeper than 64 levels"},
      {std::string(100000, '['), run_args(), 1, "nested deeper than 64 levels"},
      {with_body("\"name\": \"\xff\xfe\""), run_args(), 1, "invalid JSON"},
      {"{" + P + " // a comment\n}", run_args(), 1, "invalid JSON"},
      {with_body("\"bad\\nkey\": 1"), run_args(), 1, "bad\\x0Akey: unknown key"},
      {with_body("\"\\u001b[31mred\": 1"), run_args(), 1, "\\x1B[31mred: unknown key"},
      {force("{\"type\": \"gr\navity\"}"), run_args(), 1, "invalid JSON"},  // a raw newline
      {force(R"({"type": "gr\navity"})"), run_args(), 1, "unknown force 'gr\\x0Aavity'"},
      {with_body(R"("method": "rk4\u0007")"), run_args(), 1, "unknown method 'rk4\\x07'"},
      {with_body(R"("name": 7)"), run_args(), 1, "name: expected a string"},
      {with_body(R"("dt": "0.1")"), run_args(), 1, "dt: expected a number"},
      {"", {"run", kScenes}, 1, "is a directory"},
      {"", {"run", "/dev/zero"}, 1, "larger than 256 MiB"},
      // Values: step, counts, masses, vectors.
      {with_body(R"("dt": 0)"), run_args(), 1, "dt: expected a number > 0"},
      {with_body(R"("dt": -1)"), run_args(), 1, "dt: expected a number > 0"},
      {with_body(R"("dt": 1e-50)"), run_args(), 1, "dt: step size h must be positive and finite in float, got 0"},
      {force(R"({"type": "spring", "k": 10})").insert(1, R"("dt": 1e38, )"), run_args(), 1,
       "overflows float; take a smaller step"},
      {with_body(R"("steps": -5)"), run_args(), 1, "steps: expected an integer >= 0"},
      {with_body(R"("steps": 1.5)"), run_args(), 1, "steps: expected an integer >= 0"},
      {with_body(R"("steps": 1e30)"), run_args(), 1, "steps: expected an integer >= 0"},
      {with_body(R"("steps": 18446744073709551616)"), run_args(), 1, "steps: expected an integer >= 0"},
      {R"({"particles": [{"position": [1,0,0], "mass": 0}]})", run_args(), 1, "particles[0].mass: expected a number > 0"},
      {R"({"particles": [{"position": [1,0,0], "mass": -1}]})", run_args(), 1, "particles[0].mass: expected a number > 0"},
      {R"({"particles": [{"position": [1,0,0], "mass": 1e-50}]})", run_args(), 1, "particles[0].mass: 1e-50 has no finite nonzero inverse in float"},
      {R"({"particles": [{"position": [1,0,0], "mass": "heavy"}]})", run_args(), 1, "particles[0].mass: expected a number"},
      {R"({"particles": [{"position": [1,0]}]})", run_args(), 1, "particles[0].position: expected an array of 3"},
      {R"({"particles": [{"position": [[1],0,0]}]})", run_args(), 1, "particles[0].position[0]: expected a number"},
      {R"({"particles": [{"position": [1,0,0], "velocity": [0,"up",0]}]})", run_args(), 1, "particles[0].velocity[1]: expected a number"},
      {R"({"particles": [{"position": [1e39,0,0]}]})", run_args(), 1, "particles[0].position: (1e+39, 0, 0) overflows float"},
      {R"({"particles": [{"position": [0,0,0]}, {"position": [1,0,0], "velocity": [0,-4e38,0]}]})", run_args(), 1,
       "particles[1].velocity: (0, -4e+38, 0) overflows float"},
      // Accelerations float cannot hold: once stepped to inf (exit 3, "try a smaller dt").
      {R"({"precision": "float", "particles": [{"position": [1,0,0], "mass": 0.001, "force": [3e38,0,0]}]})", run_args(), 1,
       "particles[0].force: (3e+38, 0, 0) over the mass gives an acceleration that overflows float"},
      {R"({"precision": "float", "forces": [{"type": "gravity", "g": [0,-9.81,0]}],
          "particles": [{"position": [1,0,0], "gravity_factor": 1e38}]})", run_args(), 1,
       "particles[0].gravity_factor: 1e+38 times the gravity (0, -9.81, 0) overflows float"},
      // Paths as written: across springs terms, and for the bodies a generator made.
      {R"({"particles": [{"position": [0,0,0]}, {"position": [1,0,0]}, {"position": [2,0,0]}],
          "forces": [{"type": "springs", "pairs": [[0,1,1,1,0],[1,2,1,1,0]]}, {"type": "springs", "pairs": [[1,0,1,1,0]]}]})",
       run_args(), 1, "forces[1].pairs[0]: repeats forces[0].pairs[0] (bodies 0 and 1)"},
      // A stretched spring between two bodies at one point has no direction: refused, not
      // left to a stiffness estimate that sees its jump as a mode of 1e8 /s.
      {R"({"particles": [{"position": [0,0,0]}, {"position": [0,0,0]}, {"position": [1,0,0]}],
          "forces": [{"type": "springs", "pairs": [[1,2,1,10,0.5],[0,1,1,10,0.5]]}]})", run_args(), 1,
       "forces[0].pairs[1]: bodies 0 and 1 both start at (0, 0, 0) with rest length 1: the spring has no direction"},
      {R"({"particles": [{"position": [0,0,0]}, {"position": [0,0,0]}], "steps": 2,
          "forces": [{"type": "springs", "pairs": [[0,1,0,10,0.5]]}]})", run_args(), 0, ""},
      {R"({"forces": [{"type": "springs", "chain": {"count": 3, "spacing": 1, "k": 1}}, {"type": "springs", "pairs": [[2,1,1,1,0]]}]})",
       run_args(), 1, "forces[1].pairs[0]: repeats forces[0].chain (its spring 1) (bodies 1 and 2)"},
      {R"({"forces": [{"type": "springs", "chain": {"count": 4, "spacing": 1, "k": 1, "mass": 1e-50}}]})", run_args(), 1,
       "forces[0].chain.mass: 1e-50 has no finite nonzero inverse in float"},
      {R"({"forces": [{"type": "springs", "chain": {"count": 1000, "spacing": 1e36, "k": 1}}]})", run_args(), 1,
       "forces[0].chain.spacing: its body 341 lies at (0, -3.41e+38, 0), beyond float"},
      {R"({"precision": "double", "generate": {"count": 100, "distribution": "plummer", "radius": 1e-300, "mass": 0.01},
          "forces": [{"type": "nbody", "G": 1}]})", run_args(), 1,
       "generate.radius: 1e-300 with G M = 1: the escape speed at the centre, sqrt(2 G M / radius), overflows double"},
      {R"({"particles": [{"position": [1,0,0], "kinematic": "yes"}]})", run_args(), 1, "kinematic: expected true or false"},
      {R"({"particles": [{"velocity": [1,0,0]}]})", run_args(), 1, "particles[0]: missing key 'position'"},
      {R"({"particles": {"position": [1,0,0]}})", run_args(), 1, "particles: expected an array"},
      {R"({"particles": []})", run_args(), 1, "the scene has no bodies"},
      {"{\"partciles\": [{\"position\": [1,0,0]}]}", run_args(), 1, "partciles: unknown key"},
      {with_body(R"("precision": "half")"), run_args(), 1, "precision: expected \"float\" or \"double\""},
      {with_body(R"("method": "rk5")"), run_args(), 1, "unknown method 'rk5'"},
      {with_body(R"("method": "auto")"), run_args(), 1, "needs a tolerance"},
      {with_body(R"("method": "auto", "tolerance": 0)"), run_args(), 1, "tolerance: expected a number > 0"},
      // A stop ends kinema run's run; the charts run the whole duration: refused, not charted apart.
      {R"({"particles": [{"position": [0, 1, 0]}], "forces": [{"type": "gravity", "g": [0, -9.81, 0]}],
          "events": [{"type": "plane", "action": "stop", "direction": "down"}]})", {"chart", "{}", "-q", "--methods", "rk4", "--dts", "0.01", "--out", (work_dir() / "stop_chart").string()},
       1, "events[0] stops kinema run at its crossing; chart and stability run the whole duration and watch no events"},
      {R"({"particles": [{"position": [0, 1, 0]}], "forces": [{"type": "gravity", "g": [0, -9.81, 0]}],
          "events": [{"type": "plane", "action": "stop", "direction": "down"}]})", {"stability", "{}", "-q", "--methods", "rk4"}, 1, "events[0] stops kinema run at its crossing"},
      {R"({"particles": [{"position": [0, 1, 0]}], "forces": [{"type": "gravity", "g": [0, -9.81, 0]}],
          "events": [{"type": "plane", "action": "stop", "direction": "down"}]})", run_args({"--out", (work_dir() / "events.csv").string()}), 1,
       "/events.csv, the file --out names: one would overwrite the other"},
      // A stable step far under the run's length rules the methods out before any pilot runs
      // (error control's too: its steps cannot pass it), at once, not after minutes of pilots.
      {R"({"particles": [{"position": [0,0,0]}, {"position": [1,0,0]}], "dt": 0.01, "steps": 100,
          "forces": [{"type": "springs", "pairs": [[0,1,1,1e14,0]]}], "method": "auto", "tolerance": 1e-6})",
       run_args(), 1, "every explicit method needs over 2^22 steps to stay stable (rk6: 8.3e+06 of 1.2e-07 s)"},
      // Generation: refused from the text, before a single body is built.
      {R"({"generate": {"count": -3, "position_min": [0,0,0], "position_max": [1,1,1]}})", run_args(), 1, "generate.count: expected an integer >= 0"},
      {R"({"generate": {"count": 4294967297, "position_min": [0,0,0], "position_max": [1,1,1]}})", run_args(), 1, "expected at most 2^32 bodies"},
      {R"({"precision": "double", "generate": {"count": 4294967296, "kind": "rigid", "position_min": [0,0,0], "position_max": [1,1,1]}})",
       run_args(), 1, "generate.count: 4294967296 rigid bodies in double need 544.0 GiB of state", 64},
      {R"({"generate": {"count": 3, "position_min": [0,0,0], "position_max": [1,-1,1]}})", run_args(), 1, "generate.position_max: must not be below"},
      {R"({"generate": {"count": 3, "position_min": [0,0,0], "position_max": [1,1,1], "velocity_min": [1,0,0]}})", run_args(), 1,
       "generate.velocity_min: must not be above velocity_max (0 when left out)"},
      {R"({"generate": {"count": 3, "kind": "rigid", "position_min": [0,0,0], "position_max": [1,1,1], "angular_velocity_min": [0,0,1]}})", run_args(), 1,
       "generate.angular_velocity_min: must not be above angular_velocity_max"},
      {R"({"generate": {"count": 3, "position_min": [0,0,0], "position_max": [1,1,1], "kind": "fluid"}})", run_args(), 1, "generate.kind: expected \"particle\" or \"rigid\""},
      {R"({"generate": {"count": 3, "position_min": [0,0,0], "position_max": [1,1,1], "inertia": [1,1,1]}})", run_args(), 1, "generate.inertia: only for"},
      {R"({"generate": {"count": 3, "kind": "rigid", "position_min": [0,0,0], "position_max": [1,1,1], "inertia": [0,1,1]}})", run_args(), 1, "generate.inertia[0]: expected a number > 0"},
      {R"({"generate": {"count": 3, "seed": -1, "position_min": [0,0,0], "position_max": [1,1,1]}})", run_args(), 1, "generate.seed: expected an integer >= 0"},
      {R"({"generate": {"count": 3, "seed": 18446744073709551615, "position_min": [0,0,0], "position_max": [1,1,1]}, "steps": 2})", run_args(), 0, ""},
      {generated(R"("forces": [{"type":"central","mu":1},{"type":"central","mu":1},{"type":"central","mu":1},{"type":"central","mu":1},{"type":"central","mu":1}])"),
       run_args(), 1, "forces[4]: central: at most 4 per model", 64},
      {generated(R"("forces": [{"type":"spring","k":1e39}])"), run_args(), 1, "forces: force parameters overflow float", 64},
      {generated(R"("forces": [{"type":"spring","k":2e38}, {"type":"spring","k":2e38}])"), run_args(), 1, "force parameters overflow float", 64},
      {generated(R"("dt": 1e-50)"), run_args(), 1, "dt: step size h must be positive and finite in float", 64},
      {R"({"generate": {"count": 8388608, "mass": 1e-50, "position_min": [0,0,0], "position_max": [1,1,1]}})", run_args(), 1, "generate.mass: has no finite nonzero inverse in float", 64},
      // Coupled terms: refused from the text, before any network is built.
      {force(R"({"type": "springs", "grid": {"rows": 2000, "columns": 2000, "spacing": 1, "k": 1}})"),
       run_args(), 1, "forces[0].grid: expected at most 2^20 bodies (rows x columns)", 64},
      {force(R"({"type": "springs", "chain": {"count": 1048577, "spacing": 1, "k": 1}})"), run_args(), 1,
       "forces[0].chain.count: expected at most 2^20 bodies", 64},
      {force(R"({"type": "springs", "chain": {"count": 1048576, "spacing": 1, "k": 1}},
                {"type": "springs", "chain": {"count": 1048576, "spacing": 1, "k": 1}},
                {"type": "springs", "chain": {"count": 1048576, "spacing": 1, "k": 1}},
                {"type": "springs", "chain": {"count": 1048576, "spacing": 1, "k": 1}})"), run_args(), 1,
       "forces[3].chain: the listed particles and the bodies of every generator come to more than 2^22"},
      {force(R"({"type": "springs", "pairs": [[0, 1073741824, 1, 1, 0]]})"), run_args(), 1,
       "forces[0].pairs[0][1]: expected a body index below 2^30"},
      {force(R"({"type": "springs", "pairs": [[0, 5, 1, 1, 0]]})"), run_args(), 1,
       "forces[0].pairs[0]: joins body 5, but the scene has 1 particles"},
      {force(R"({"type": "nbody", "G": 1e39})"), run_args(), 1, "nbody.G: 1e+39 overflows float"},
      {R"({"generate": {"count": 8388608, "position_min": [0,0,0], "position_max": [1e39,1,1]}})", run_args(), 1, "generate.position_max: overflows float", 64},
      {R"({"generate": {"count": 8388608, "kind": "rigid", "position_min": [0,0,0], "position_max": [1,1,1], "angular_velocity_max": [3e38,0,0]}})",
       run_args(), 1, "angular momentum it gives overflows float", 64},
      {R"({"generate": {"count": 8388608, "kind": "rigid", "position_min": [0,0,0], "position_max": [1,1,1], "inertia": [1e-39,1,1]}})",
       run_args(), 1, "generate.inertia: a moment has no finite inverse in float", 64},
      // Force terms.
      {force(R"({"type": "magnet"})"), run_args(), 1, "forces[0].type: unknown force 'magnet'"},
      {force(R"({"k": 1})"), run_args(), 1, "forces[0]: missing key 'type'"},
      {force(R"({"type": "gravity", "g": 9.81})"), run_args(), 1, "forces[0].g: expected an array of 3"},
      {force(R"({"type": "gravity", "g": [0,0,0]}, {"type": "spring", "k": -4})"), run_args(), 1, "forces[1].k: expected a number >= 0"},
      {force(R"({"type": "spring", "k": 1, "anchor": [0,0]})"), run_args(), 1, "forces[0].anchor: expected an array of 3"},
      {force(R"({"type": "spring", "k": 1, "stiffness": 2})"), run_args(), 1, "forces[0].stiffness: unknown key"},
      {force(R"({"type": "central", "mu": -1})"), run_args(), 1, "forces[0].mu: expected a number >= 0"},
      {force(R"({"type": "linear_drag", "k": 1e39})"), run_args(), 1, "force parameters overflow float"},
      {force(R"({"type": "torque", "torque": 1})"), run_args(), 1, "forces[0].torque: expected an array of 3"},
      {force(R"({"type": "angular_drag", "c": -1})"), run_args(), 1, "forces[0].c: expected a number >= 0"},
      {force(R"({"type": "point_force", "point": [0,0,0]})"), run_args(), 1, "forces[0]: missing key 'force'"},
      {R"({"rigid_bodies": [{"position": [1,0,0]}], "forces": [{"type":"point_force","point":[0,0,0],"force":[1,0,0]},{"type":"point_force","point":[0,0,0],"force":[1,0,0]},{"type":"point_force","point":[0,0,0],"force":[1,0,0]},{"type":"point_force","point":[0,0,0],"force":[1,0,0]},{"type":"point_force","point":[0,0,0],"force":[1,0,0]}]})",
       run_args(), 1, "forces[4]: point_force: at most 4"},
      {with_body(R"("forces": {"type": "gravity"})"), run_args(), 1, "forces: expected an array"},
      // Rigid bodies.
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[5e307,5e307,0],[5e307,5e307,0],[0,0,1e308]]}]})", run_args(), 1, "rigid_bodies[0].inertia: the tensor is singular"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[1,1,0],[1,1,0],[0,0,1]]}]})", run_args(), 1, "the tensor is singular"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[1e308,1e308,0],[-1e308,1e308,0],[0,0,1e308]]}]})", run_args(), 1, "the tensor is not symmetric"},
      {R"({"precision": "float", "dt": 4, "rigid_bodies": [{"position": [0,0,0], "mass": 1e10}],
          "forces": [{"type": "point_force", "point": [0,0,0], "force": [2e38,0,0]}]})", run_args(), 1, "overflows float; take a smaller step"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[1,0.5,0],[0,1,0],[0,0,1]]}]})", run_args(), 1, "the tensor is not symmetric"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[2,0,0],[0,-1,0],[0,0,2]]}]})", run_args(), 1, "not positive definite"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [[7e307,3e307,0],[3e307,7e307,0],[0,0,7e307]]}], "precision": "double", "steps": 2})", run_args(), 0, ""},
      {R"({"rigid_bodies": [{"position": [0,0,0], "inertia": [1,1]}]})", run_args(), 1, "rigid_bodies[0].inertia: expected [Ixx, Iyy, Izz] or a 3x3 matrix"},
      {R"({"precision": "float", "rigid_bodies": [{"position": [0,0,0], "inertia": [1e-39, 1, 1]}]})", run_args(), 1, "an inertia moment has no finite inverse"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "orientation": [0,0,0,0]}]})", run_args(), 1, "rigid_bodies[0].orientation: the quaternion is zero"},
      {R"({"rigid_bodies": [{"position": [0,0,0], "orientation": [1e-200,0,0,0]}], "steps": 2})", run_args(), 0, ""},
      {R"({"rigid_bodies": [{"position": [0,0,0], "orientation": [1e300,1e300,0,0]}], "steps": 2})", run_args(), 0, ""},
      {R"({"rigid_bodies": [{"position": [0,0,0], "angular_velocity": [1,0,0], "angular_momentum": [1,0,0]}]})", run_args(), 1, "angular_velocity or angular_momentum, not both"},
      {R"({"particles": [{"position": [0,1,0]}], "events": [{"type": "plane", "normal": [0, 1e-300, 0]}]})", run_args(), 1, ".json: events[0]: plane normal's squared length underflows double"},
      // Runaway searches: refused at once, or bounded.
      {"", {"run", kSpring, "-q", "--method", "auto", "--tolerance", "1e-300"}, 1, "is below the round-off of one step in double"},
#ifndef KINEMA_SANITIZED  // 1 s of pilot runs here, over 3 minutes unoptimized under ASan
      {R"({"precision": "float", "rigid_bodies": [{"position": [0,0,0], "angular_velocity": [3e37, 1e37, 0], "inertia": [1,2,3]}], "method": "auto", "tolerance": 1e-3})",
       run_args(), 1, "auto: no method reaches tolerance 0.001"},
#endif
      {"", {"run", kSpring, "-q", "--method", "auto", "--tolerance", "1e-6", "--steps", "1099511627776", "--dt", "1e-9"}, 1,
       "auto: no method reaches tolerance 1e-06 within 2^22 steps or 2^28 body-steps"},
  };
}

std::vector<Case> option_cases() {
  const std::string scene = kSpring;
  const std::string cluster = std::string(KINEMA_SCENES) + "/plummer_cluster.json";
  auto run = [&](std::vector<std::string> extra) {
    std::vector<std::string> a{"run", scene, "-q"};
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  };
  return {
      {"", run({"--steps", "0x10"}), 2, "--steps: expected a decimal integer"},
      {"", run({"--steps", "18446744073709551616"}), 2, "--steps: expected 0 to 18446744073709551615"},
      {"", run({"--steps", "-1"}), 2, "--steps: expected a decimal integer"},
      {"", run({"--steps", "1e3"}), 2, "--steps: expected a decimal integer"},
      {"", run({"--steps", "+5"}), 2, "--steps: expected a decimal integer"},
      {"", run({"--steps", ""}), 2, "--steps"},
      {"", run({"--steps", "many"}), 2, "--steps"},
      {"", run({"--steps"}), 2, "--steps"},
      {"", run({"--every", "5"}), 2, "--every requires --out"},
      {"", run({"--tolerance", "1e-3"}), 1, "--tolerance bounds the error of --method auto's choice; the method here is rk4"},
      {"", run({"--implicit-iterations", "5"}), 1, "set the linear solves of implicit_euler and ros2; the method here is rk4"},
      {"", run({"--implicit-preconditioner", "jacobi", "--method", "dopri5"}), 1, "the method here is dopri5"},
      {"", run({"--implicit-preconditioner", "automatic"}), 1, "the method here is rk4"},
      // NaN passed CLI11's range and was refused later as the scene's fault (exit 1).
      {"", run({"--method", "implicit_euler", "--implicit-tolerance", "nan"}), 2,
       "--implicit-tolerance: expected a number from 1e-300 to 0.5, got 'nan'"},
      {"", run({"--method", "implicit_euler", "--implicit-tolerance", "0"}), 2, "expected a number from 1e-300 to 0.5"},
      {"", run({"--method", "implicit_euler", "--implicit-iterations", "1e3"}), 2,
       "--implicit-iterations: expected a decimal integer"},
      // auto once ran its choice with a looser solve than its pilots measured.
      {"", run({"--method", "auto", "--tolerance", "1e-3", "--implicit-tolerance", "0.4"}), 1,
       "set the linear solves of a named implicit method; --method auto chooses with the default solves"},
      {"", run({"--isa", "avx2", "--relaxed-fma"}), 1, "--relaxed-fma changes the scalar and SSE2 kernels; --isa avx2 always uses its FMA units"},
      {"", run({"--isa", "scalar", "--relaxed-fma", "--steps", "3"}), 0, ""},  // scalar: in every build
      {"", run({"--every", "0"}), 2, "--every: expected 1 to"},
      {"", run({"--every", "0x1"}), 2, "--every: expected a decimal integer"},
      {"", run({"--threads", "2000"}), 2, "--threads: expected 0 to 1024"},
      {"", run({"--threads", "-2"}), 2, "--threads"},
      {"", run({"--dt", "0"}), 2, "--dt: expected a finite number > 0, got '0'"},
      {"", run({"--dt", "-1"}), 2, "--dt: expected a finite number > 0"},
      {"", run({"--dt", "nan"}), 2, "--dt: expected a finite number > 0"},
      {"", run({"--dt", "1e-50", "--precision", "float"}), 1, "--dt 1e-50 rounds to 0 in float"},
      {"", run({"--dt", "1e39", "--precision", "float"}), 1, "--dt 1e+39 overflows in float"},
      {"", {"stress", "-q", "--bodies", "100", "--steps", "2", "--dt", "1e308"}, 1, "--dt 1e+308 overflows in float"},
      {"", run({"--dt", "inf"}), 2, "--dt: expected a finite number > 0"},
      {"", run({"--dt", "1e400"}), 2, "--dt: expected a finite number > 0"},
      {"", run({"--dt", "0x1p-3"}), 2, "--dt: expected a finite number > 0"},
      {"", run({"--dt", "1e-400"}), 2, "--dt: expected a finite number > 0"},
      {"", run({"--tolerance", "0"}), 2, "--tolerance: expected a finite number > 0"},
      {"", run({"--out", ""}), 2, "--out: expected a path"},
      {"", run({"--summary", ""}), 2, "--summary: expected a path"},
      {"", run({"--isa", "neon"}), 2, "--isa"},
      {"", run({"--precision", "half"}), 2, "--precision"},
      {"", run({"--frobnicate"}), 2, "--frobnicate"},
      {"", run({"--method", "bogus"}), 1, "unknown method 'bogus'"},
      {"", run({"--method", "rk4\n--evil"}), 1, "unknown method 'rk4\\x0A--evil'"},
      {"", run({"--method", "\x1b]0;title\x07"}), 1, "unknown method '\\x1B]0;title\\x07'"},
      {"", run({"--steps", "010", "--threads", "0002"}), 0, ""},
      {"", run({"--threads", "64", "--steps", "3"}), 0, ""},
      {"", {"run", ""}, 2, "expected a path"},
      {"", {"run"}, 2, "scene is required"},
      {"", {}, 2, "A subcommand is required"},
      {"", {"fly", scene}, 2, "unknown command 'fly': run, chart, stability or stress"},
      {"", {"chart", scene, "--out", "/etc/passwd", "--methods", "rk4", "--dts", "0.1", "--duration", "1"}, 1,
       "--out /etc/passwd: cannot create the folder (Not a directory)"},
      {"", {"stability", scene, "--out", "/etc/passwd", "--methods", "rk4"}, 1, "--out /etc/passwd: cannot create the folder"},
      {"", {"chart", scene, "--bodies", "0"}, 2, "--bodies: expected 1 to"},
      {"", {"chart", scene, "--repeat", "101"}, 2, "--repeat: expected 1 to 100"},
      {"", {"chart", scene, "--dts", "0.1,inf"}, 2, "--dts: expected a finite number > 0"},
      // A step float cannot hold was the scene's "step size h must be positive ... got 0".
      {"", {"chart", scene, "--dts", "1e-46", "--duration", "1e-44", "--precision", "float", "--out",
            (work_dir() / "tiny_chart").string()}, 1, "--dts 1e-46 rounds to 0 in float"},
      // CLI11's delimiter dropped empty items: ",euler" ran euler alone.
      {"", {"chart", scene, "--methods", ",euler"}, 2, "--methods: an empty item in ',euler'"},
      {"", {"stability", scene, "--methods", "euler,,rk4"}, 2, "--methods: an empty item in 'euler,,rk4'"},
      {"", {"chart", scene, "--dts", "0.1,"}, 2, "--dts: an empty item in '0.1,' (a comma at an end, or two together)"},
      {"", {"chart", scene, "--duration", "-1"}, 2, "--duration: expected a finite number > 0"},
      {"", {"chart", scene, "--out", ""}, 2, "--out: expected a path"},
      {"", {"chart", scene, "-q", "--dts", "1e300"}, 1, "a step of 1e+300 s over 20 s is longer than the duration"},
      {"", {"chart", scene, "-q", "--dts", "1e-30"}, 1, "takes more than 2^32 steps"},
      {"", {"chart", scene, "-q", "--methods", "rk9"}, 1, "unknown method 'rk9'"},
      {"", {"stability", scene, "--bodies", "0"}, 2, "--bodies: expected 1 to"},
      {"", {"stability", scene, "--dt", "nan"}, 2, "--dt: expected a finite number > 0"},
      {"", {"stability", scene, "-q", "--dt", "100"}, 1, "is longer than the duration"},
      // The bisection's product lo hi underflowed to 0: "a step of 0 s ... takes more than 2^32 steps".
      {"", {"stability", std::string(KINEMA_SCENES) + "/kepler_circular.json", "-q", "--methods", "rk4", "--dt", "1e-200",
            "--duration", "1e-199", "--out", (work_dir() / "tiny_stability").string()}, 0, ""},
      // Hours of work, refused before the first run (SIGINT would end them, but nothing more).
      {"", {"chart", cluster, "-q", "--out", (work_dir() / "refused_chart").string()}, 1,
       "plummer_cluster.json: the chart would take about 3.2e+13 body-evaluations (3.79e+06 force evaluations of "
       "8.39e+06 each), more than the 1.1e+12 it may spend; give fewer or longer --dts"},
      {"", {"stability", cluster, "-q", "--out", (work_dir() / "refused_stability").string()}, 1,
       "plummer_cluster.json: stability would take about 2.1e+12 body-evaluations"},
      // Outputs that cannot be written: refused before the run, naming the file.
      {"", run({"--summary", "/dev/full"}), 1, "/dev/full: cannot write the summary: No space left on device"},
      {"", run({"--out", "/dev/full"}), 1, "/dev/full: cannot write the trajectory: No space left on device"},
      {"", run({"--out", "/nonexistent/dir/t.csv"}), 1, "/nonexistent/dir/t.csv: cannot write the trajectory"},
      {"", run({"--out", "/dev/null", "--checkpoint", (work_dir() / "never.ck").string()}), 1,
       "--out /dev/null: with --checkpoint the trajectory is a file that a resumed run continues, not a device, a pipe "
       "or a standard stream"},
      {"", run({"--out", "/dev/stderr", "--checkpoint", (work_dir() / "never.ck").string()}), 1,
       "--out /dev/stderr: with --checkpoint the trajectory is a file that a resumed run continues"},
      // Steps that would take the clock past every double.
      {"", run({"--dt", "1e305", "--steps", "100000"}), 1, "dt x steps (100000 steps of 1e+305 s) overflows the clock"},
      {R"({"steps": 10, "events": [{"type": "plane", "normal": [0, 1, 0], "offset": 0}], )" + P + "}",
       {"run", "{}", "-q", "--out", "/dev/null"}, 1,
       "its events go to events.csv beside the trajectory, and --out /dev/null is no file in a folder"},
      {R"({"steps": 10, "events": [{"type": "plane", "normal": [0, 1, 0], "offset": 0}], )" + P + "}",
       {"run", "{}", "-q", "--out", "/dev/stderr"}, 1, "is no file in a folder (a device, a pipe or a standard stream)"},
      // Under error control dt is the output interval: a pull whose product with dopri5's
      // weights would overflow float at a step of dt is no reason to refuse the run.
      {R"({"precision": "float", "method": "dopri5", "rtol": 1e-3, "dt": 1, "steps": 1,
           "forces": [{"type": "gravity", "g": [0, -2e37, 0]}], )" + P + "}", {"run", "{}", "-q"}, 0, ""},
      // The default sweep leaves out steps longer than a one-step scene's duration.
      {R"({"steps": 1, "precision": "double", "forces": [{"type": "central", "mu": 1}], )" + P + "}",
       {"chart", "{}", "-q", "--methods", "rk4", "--out", (work_dir() / "one_step_chart").string()}, 0, ""},
      // The scene's own method is kinema run's: its refusal with events once stopped a chart.
      {R"({"steps": 4, "dt": 0.01, "method": "implicit_euler", "precision": "double",
           "forces": [{"type": "spring", "anchor": [0, 0, 0], "k": 4}],
           "events": [{"type": "plane", "normal": [0, 1, 0], "offset": -1}], )" + P + "}",
       {"chart", "{}", "-q", "--methods", "rk4", "--dts", "0.01", "--out", (work_dir() / "implicit_scene_chart").string()},
       0, ""},
      // No default step within the duration: once "every error is zero or not finite".
      {R"({"steps": 1, "dt": 1, "precision": "double", "forces": [{"type": "central", "mu": 1}], )" + P + "}",
       {"chart", "{}", "-q", "--methods", "rk4", "--duration", "0.001"}, 1,
       "the scene's dt (1 s) times 1/8 .. 16 gives no step within the duration (0.001 s): give --dts or a longer --duration"},
      // What stress would not do with a scene is refused, not skipped.
      {R"({"steps": 10, "events": [{"type": "plane", "normal": [0, 1, 0], "offset": 0, "action": "stop"}], )" + P + "}",
       {"stress", "-q", "--scene", "{}"}, 1, "stress watches no events: kinema run takes a scene's \"events\""},
      {R"({"method": "dopri5", "rtol": 1e-6, "steps": 10, )" + P + "}", {"stress", "-q", "--scene", "{}"}, 1,
       "stress takes fixed steps of dt: kinema run takes a scene's \"rtol\" and \"atol\""},
      {"", run({"--summary", "/"}), 1, "/: cannot write the summary"},
      {"", {"chart", scene, "-q", "--out", "/dev/null/charts"}, 1, "/dev/null/charts"},
      {"", {"stability", scene, "-q", "--out", "/dev/null/charts"}, 1, "/dev/null/charts"},
      // Charts of scenes with nothing to draw on log axes.
      {R"({"particles": [{"position": [0,0,0]}], "steps": 10})", {"chart", "{}", "-q", "--repeat", "1", "--out", (work_dir() / "still_chart").string()}, 1,
       "no chart: every error is zero or not finite"},
      {R"({"particles": [{"position": [1,0,0]}], "forces": [{"type": "linear_drag", "k": 1}], "steps": 10})",
       {"stability", "{}", "-q", "--out", (work_dir() / "still_stability").string()}, 1, "no energy chart"},
  };
}

}  // namespace

TEST_CASE("hostile scenes and options: the exit code and one clear line each", "[cli][hostile]") {
  std::vector<Case> cases = scene_cases();
  const std::vector<Case> options = option_cases();
  cases.insert(cases.end(), options.begin(), options.end());
  CHECK(cases.size() > 100);
  // The program's own footprint (large under ASan) is the baseline for the memory checks.
  const long baseline_kib = run_kinema({"--help"}).peak_kib;
  int index = 0;
  for (Case c : cases) {
    const std::string file = "hostile" + std::to_string(index++) + ".json";
    if (!c.scene.empty()) {
      const std::string path = write(file, c.scene).string();
      std::replace(c.args.begin(), c.args.end(), std::string("{}"), path);
    }
    const Result r = run_kinema(c.args);
    CHECK_FALSE(r.killed);
    std::string shown;
    for (const auto& a : c.args) shown += " [" + a.substr(0, 80) + "]";
    INFO("case " << index - 1 << ":" << shown << "\nscene: " << c.scene.substr(0, 200)
                 << "\nstderr: " << r.err);
    CHECK(r.code == c.code);
    CHECK_FALSE(has_raw_control(r.err));
    if (c.message.empty()) {
      CHECK(r.err.empty());
    } else {
      CHECK(lines(r.err) == 1);
      CHECK(r.err.rfind("kinema: error: ", 0) == 0);
      CHECK(r.err.find(c.message) != std::string::npos);
      CHECK(r.err.size() < 400);  // no 309-digit ranges
      if (!c.scene.empty() && c.code == 1 && c.args[0] == "run") {
        CHECK(r.err.find(file) != std::string::npos);  // names the file
      }
    }
    if (c.peak_mib > 0) CHECK(r.peak_kib - baseline_kib < c.peak_mib * 1024);
  }
}

namespace {

std::vector<std::string> split(const std::string& line, char by) {
  std::vector<std::string> cells;
  std::istringstream in(line);
  for (std::string cell; std::getline(in, cell, by);) cells.push_back(cell);
  return cells;
}

// Every cell after the header reads as a whole number, with nothing left over.
bool whole_numbers(const std::vector<std::string>& cells) {
  for (const std::string& cell : cells) {
    char* end = nullptr;
    std::strtod(cell.c_str(), &end);
    if (cell.empty() || *end != '\0') return false;
  }
  return true;
}

}  // namespace

TEST_CASE("a signal stops a run at a step boundary: whole lines, a complete last step, the summary", "[cli][hostile][signals]") {
  // 1000 bodies for up to 10^7 steps, every step written: far longer than the test waits.
  const fs::path scene = write("long.json", R"({"dt": 0.001, "steps": 10000000,
      "generate": {"count": 1000, "position_min": [0,0,0], "position_max": [1,1,1]},
      "forces": [{"type": "gravity", "g": [0,-9.81,0]}]})");
  for (const int signal : {SIGINT, SIGTERM}) {
    INFO("signal " << signal);
    const fs::path csv = work_dir() / "interrupted.csv", summary = work_dir() / "interrupted.json";
    fs::remove(csv);
    const Result r = run_kinema(
        {"run", scene.string(), "-q", "--every", "1", "--out", csv.string(), "--summary", summary.string()}, {},
        [&](pid_t pid) {
          // Past the first 4 KiB buffers, where a killed run used to cut a number in half
          // (a minute at most: a run that ended early fails the checks below).
          const auto give_up = std::chrono::steady_clock::now() + std::chrono::minutes(1);
          while ((!fs::exists(csv) || fs::file_size(csv) < 200000) &&
                 std::chrono::steady_clock::now() < give_up) {
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
          }
          ::kill(pid, signal);
        });
    CHECK_FALSE(r.killed);  // it exited by itself, at a step boundary
    CHECK(r.code == 128 + signal);
    CHECK(r.err.find(signal == SIGINT ? "stopped by SIGINT after step" : "stopped by SIGTERM after step") !=
          std::string::npos);
    CHECK(r.err.find("; the outputs are complete to there") != std::string::npos);
    std::istringstream in(read(csv));
    std::string line;
    std::getline(in, line);
    REQUIRE(line == "step,t,body,px,py,pz,vx,vy,vz");
    std::map<long, int> rows_per_step;
    bool whole = true;
    while (std::getline(in, line)) {
      const auto cells = split(line, ',');
      whole = whole && cells.size() == 9 && whole_numbers(cells);
      ++rows_per_step[std::stol(cells.at(0))];
    }
    CHECK(whole);
    REQUIRE_FALSE(rows_per_step.empty());
    for (const auto& [step, rows] : rows_per_step) REQUIRE(rows == 1000);  // no step cut short
    const auto j = nlohmann::json::parse(read(summary));
    CHECK(j["interrupted"] == (signal == SIGINT ? "SIGINT" : "SIGTERM"));
    CHECK(j["steps"] == rows_per_step.rbegin()->first);  // the summary's last step is the file's
    CHECK(j["steps_requested"] == 10000000);
    CHECK(j["finite"] == true);
  }
}

TEST_CASE("a signal with no output asked for: the message claims none", "[cli][hostile][signals]") {
  const fs::path scene = write("long_quiet.json", R"({"dt": 0.001, "steps": 100000000,
      "generate": {"count": 1000, "position_min": [0,0,0], "position_max": [1,1,1]}})");
  const Result r = run_kinema({"run", scene.string(), "-q"}, {}, [](pid_t pid) {
    wait_until_catching(pid, SIGINT);
    std::this_thread::sleep_for(std::chrono::milliseconds(1000));
    ::kill(pid, SIGINT);
  });
  CHECK(r.code == 128 + SIGINT);
  CHECK(r.err.find("kinema: stopped by SIGINT after step") == 0);
  CHECK(r.err.find("complete") == std::string::npos);
}

TEST_CASE("the long analyses answer a signal: chart and stability runs, auto's pilots, the stiffness estimate",
          "[cli][hostile][signals]") {
  const std::string cluster = std::string(KINEMA_SCENES) + "/plummer_cluster.json";
  const std::string cloth = std::string(KINEMA_SCENES) + "/cloth.json";
  // Each takes minutes, within the work bound: chart's reference on the cluster (rk4 at 64 x
  // the most steps swept), stability's bisections, auto's pilots on the stiff cloth, and the estimate before
  // the first step of 16384 bodies' pairs.
  // (4096 under the sanitizers: the summary's O(N^2) energy sums alone would take a minute.)
#ifdef KINEMA_SANITIZED
  const std::string bodies = R"("count": 4096, "mass": 0.000244140625)";
#else
  const std::string bodies = R"("count": 16384, "mass": 6.103515625e-05)";
#endif
  const fs::path big = write("big_cluster.json", R"({"dt": 0.002, "steps": 500, "precision": "double",
      "generate": {"seed": 7, "distribution": "plummer", "radius": 1, )" + bodies + R"(},
      "forces": [{"type": "nbody", "G": 1, "softening": 0.05}]})");
  const std::vector<std::vector<std::string>> commands = {
      {"chart", cluster, "-q", "--dts", "0.004", "--repeat", "1", "--duration", "0.5", "--out",
       (work_dir() / "signal_chart").string()},
      {"stability", cluster, "-q", "--duration", "0.5", "--methods", "rk4,velocity_verlet", "--out",
       (work_dir() / "signal_stability").string()},
      {"run", cloth, "-q", "--method", "auto", "--tolerance", "1e-5"},
      {"run", big.string(), "-q"}};
  for (const auto& args : commands) {
    INFO(args[0] << " " << args[1]);
    const Result r = run_kinema(args, {}, [](pid_t pid) {
      wait_until_catching(pid, SIGINT);
      std::this_thread::sleep_for(std::chrono::milliseconds(700));
      ::kill(pid, SIGINT);
      // A minute to answer, then it is killed (and the test fails: it did not exit by itself).
      for (int k = 0; k < 600; ++k) {
        siginfo_t info{};
        if (::waitid(P_PID, id_t(pid), &info, WEXITED | WNOHANG | WNOWAIT) == 0 && info.si_pid == pid) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
      ::kill(pid, SIGKILL);
    });
    CHECK_FALSE(r.killed);
    CHECK(r.code == 128 + SIGINT);
    CHECK(r.err.find("kinema: stopped by SIGINT") == 0);
  }
}

namespace {

// `kinema run scene -q` under an address-space limit of `kib`: its stderr, once it exited 1.
std::string refused_under_limit(const fs::path& scene, long kib) {
  const fs::path err = work_dir() / "limited_stderr.txt";
  const std::string command = "ulimit -v " + std::to_string(kib) + " && exec '" + std::string(KINEMA_CLI) + "' run '" +
                              scene.string() + "' -q --threads 1 2> '" + err.string() + "'";
  const int status = std::system(command.c_str());
  REQUIRE(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 1);
  const std::string text = read(err);
  CHECK(lines(text) == 1);
  CHECK(text.find("this process may use") != std::string::npos);
  return text;
}

}  // namespace

TEST_CASE("a scene that would not fit is refused before it is built, naming what it needs", "[cli][hostile][memory]") {
  // A 512 x 512 cloth (about 700 MiB at its peak: the springs' layouts and the stiffness
  // estimate, not its 7 MiB of state) under a 400 MB address-space limit: this used to end in
  // a bare std::bad_alloc after seconds of work.
#ifdef KINEMA_SANITIZED
  SUCCEED("sanitizers reserve terabytes of address space: ulimit -v cannot be tested there");
  return;
#endif
  const fs::path scene = write("big_grid.json", R"({"steps": 1000, "dt": 0.0001,
      "forces": [{"type": "springs", "grid": {"rows": 512, "columns": 512, "spacing": 1, "k": 10}}]})");
  const std::string text = refused_under_limit(scene, 400000);
  CHECK(text.find("big_grid.json: the scene needs about ") != std::string::npos);
  CHECK(text.find(" for its springs, ") != std::string::npos);
}

TEST_CASE("the memory check counts the stages of a method without a fused kernel", "[cli][hostile][memory]") {
  // 4M float particles: about 0.4 GiB for rk4, 1.3 GiB under rk6, whose stages stay in
  // memory. The check counted stages only for coupled terms: rk6 passed it here and then ran
  // out of memory after building the set.
#ifdef KINEMA_SANITIZED
  SUCCEED("sanitizers reserve terabytes of address space: ulimit -v cannot be tested there");
  return;
#endif
  const fs::path scene = write("many_rk6.json", R"({"method": "rk6", "steps": 1,
      "generate": {"count": 4000000, "position_min": [-1, -1, -1], "position_max": [1, 1, 1]}})");
  const std::string text = refused_under_limit(scene, 1000000);
  CHECK(text.find("many_rk6.json: the scene needs about 1.3 GiB") != std::string::npos);
  CHECK(text.find("for the stiffness estimate and the stages") != std::string::npos);
}

TEST_CASE("a stiffness estimate that would cost more than the run is left out, and the summary says so",
          "[cli][hostile]") {
  // 65536 bodies and 260610 springs for one step: the estimate's 57 evaluations in double
  // and its Krylov vectors would be most of the run's time and memory.
  const fs::path scene = write("one_step_grid.json", R"({"steps": 1, "dt": 0.0001,
      "forces": [{"type": "springs", "grid": {"rows": 256, "columns": 256, "spacing": 1, "k": 10}}]})");
  const fs::path summary = work_dir() / "one_step_grid_summary.json";
  const Result r = run_kinema({"run", scene.string(), "--summary", summary.string()});
  CHECK(r.code == 0);
  CHECK(r.err.find("kinema: note: the stiffness estimate would cost more than the run's 1 steps; left out") == 0);
  const auto j = nlohmann::json::parse(read(summary));
  CHECK(j["stiffness"].is_null());
  CHECK_FALSE(j.contains("largest_stable_step"));
  CHECK(j["complete"] == true);
  // Quiet: no note; the summary still says it.
  CHECK(run_kinema({"run", scene.string(), "-q"}).err.empty());
}

TEST_CASE("more threads than cores: silent with -q, and the summary says what ran", "[cli][hostile]") {
  // Past inline_below, so the job system runs; oneTBB used to warn on stderr.
  const fs::path scene = write("threads.json", R"({"steps": 3,
      "generate": {"count": 20000, "position_min": [0,0,0], "position_max": [1,1,1]}})");
  const fs::path summary = work_dir() / "threads_summary.json";
  const Result r = run_kinema({"run", scene.string(), "-q", "--threads", "64", "--summary", summary.string()});
  CHECK(r.code == 0);
  CHECK(r.err.empty());
  CHECK(r.out.empty());
  CHECK(nlohmann::json::parse(read(summary))["threads"] == kinema::hardware_threads());
}

TEST_CASE("an error message stays one bounded line, however long the text in it", "[cli][hostile]") {
  const std::string key(100000, 'k');
  const fs::path scene = write("long_key.json", R"({"particles": [{"position": [1,0,0]}], ")" + key + R"(": 1})");
  const Result r = run_kinema({"run", scene.string(), "-q", "--method", std::string(100000, 'm')});
  CHECK(r.code == 1);
  CHECK(lines(r.err) == 1);
  CHECK(r.err.size() < 1100);
  CHECK(r.err.find("more bytes)") != std::string::npos);
}

TEST_CASE("a full standard output is an error, not a silent success", "[cli][hostile]") {
  const Result r = run_kinema({"run", kSpring}, "/dev/full");
  CHECK(r.code == 1);
  CHECK(r.err == "kinema: error: standard output: cannot write: No space left on device\n");
}

TEST_CASE("/dev/stdout redirected to a file takes the outputs after what the program printed", "[cli][hostile]") {
  // Replacing the file the stream is open on (as a summary file is replaced) lost the text
  // summary; opening it anew (as the trajectory was) wrote over it from the start.
  const fs::path printed = work_dir() / "redirected.txt";
  const Result summary = run_kinema({"run", kSpring, "--steps", "3", "--summary", "/dev/stdout"}, printed);
  REQUIRE(summary.code == 0);
  const std::string both = read(printed);
  CHECK(both.find("\"scene\"") != std::string::npos);       // the JSON
  CHECK(both.find("state_crc32c") != std::string::npos);     // and the text summary
  const fs::path file = work_dir() / "trajectory-file.csv";
  REQUIRE(run_kinema({"run", kSpring, "--steps", "3", "-q", "--out", file.string()}).code == 0);
  REQUIRE(run_kinema({"run", kSpring, "--steps", "3", "--out", "/dev/stdout"}, printed).code == 0);
  const std::string mixed = read(printed);
  CHECK(mixed.find(read(file)) != std::string::npos);  // every trajectory line, in order
  CHECK(mixed.find("state_crc32c") != std::string::npos);
}

TEST_CASE("a FIFO no reader has open is refused at once as the trajectory", "[cli][hostile]") {
  // A blocking open would wait for a reader for ever (and restart after a first signal).
  const fs::path fifo = work_dir() / "no-reader.fifo";
  fs::remove(fifo);
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const Result r = run_kinema({"run", kSpring, "-q", "--out", fifo.string()});
  CHECK(r.code == 1);
  CHECK_THAT(r.err, Catch::Contains("cannot write the trajectory: a FIFO that no reader has open"));
  fs::remove(fifo);
}

TEST_CASE("a blow-up names the very step, body and component", "[cli][hostile]") {
  // Explicit Euler on v' = -30 v with h = 0.1: v is multiplied by -2 each step, so in float
  // |v| = 2^n first overflows at step 128 (FLT_MAX < 2^128); x stays finite one step longer.
  const fs::path scene = write("spiral.json", R"({"precision": "float", "method": "euler", "dt": 0.1,
      "steps": 1000, "particles": [{"position": [0,0,0]}, {"position": [1,0,0], "velocity": [1,0,0]}],
      "forces": [{"type": "linear_drag", "k": 30}]})");
  const fs::path summary = work_dir() / "spiral_summary.json";
  const Result r = run_kinema({"run", scene.string(), "-q", "--summary", summary.string()});
  CHECK(r.code == 3);
  CHECK(r.err.find("no longer finite after step 128 (t = 12.8): body 1, vx") != std::string::npos);
  const auto j = nlohmann::json::parse(read(summary));
  CHECK(j["finite"] == false);
  CHECK(j["first_non_finite"]["step"] == 128);
  CHECK(j["first_non_finite"]["body"] == 1);
  CHECK(j["first_non_finite"]["field"] == "vx");
  CHECK(j["error"] == "the state is no longer finite after step 128 (t = 12.8): body 1, vx");  // what ended it
  CHECK(j["complete"] == false);
  CHECK(j["steps"].get<int>() >= 128);  // the run stops soon after, not at step 1000
  CHECK(j["steps"].get<int>() < 1000);
}

TEST_CASE("chart and stability: no name or path can become a gnuplot command", "[cli][hostile][chart]") {
  const fs::path marker = work_dir() / "pwned";
  const std::string payload = "system \"touch " + marker.string() + "\"";
  // A name that closes its string and starts a new line, quotes, macros, backquotes,
  // escapes, a C1 control and invalid UTF-8.
  const std::string name = "x'\n" + payload + "\n'@GPVAL_TERM `touch " + marker.string() +
                           "` \\ \x1b[31m \xc2\x85 \xff end";
  nlohmann::json scene = {{"name", name}, {"steps", 40},
                          {"particles", {{{"position", {1, 0, 0}}, {"velocity", {0, 1, 0}}}}},
                          {"forces", {{{"type", "central"}, {"mu", 1}}}}};
  const fs::path file = write("inject.json", scene.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  const std::vector<std::string> outs = {(work_dir() / ("o\n" + payload + "\n'")).string(), "-x-charts",
                                         (work_dir() / "o'; `touch pwned`").string()};
  for (const std::string& out : outs) {
    for (const char* command : {"chart", "stability"}) {
      INFO(command << " --out " << out);
      fs::remove_all(out);
      std::vector<std::string> args{command, file.string(), "-q", "--methods", "euler,rk4", "--out=" + out};
      if (std::string(command) == "chart") args.insert(args.end(), {"--repeat", "1"});
      const Result r = run_kinema(args);
      CHECK(r.code == 0);
      CHECK(r.err.empty());
      CHECK_FALSE(fs::exists(marker));
      const std::string chart = std::string(command) == "chart" ? "work_precision.svg" : "energy.svg";
      REQUIRE(fs::exists(fs::path(out) / chart));
      // The title is the name, escaped, as text of the chart.
      CHECK(read(fs::path(out) / chart).find("x'\\x0Asystem") != std::string::npos);
    }
  }
  fs::remove_all("-x-charts");
}
