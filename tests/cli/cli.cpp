// The kinema program end to end: trajectory CSV, summary JSON, and one clear error line
// with a non-zero exit for every malformed scene or option.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <complex>
#include <filesystem>
#include <map>
#include <numbers>
#include <fstream>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli_support.hpp"
#include "kinema/scenes.hpp"

namespace fs = std::filesystem;
using namespace kinema;

namespace {

using test::read;
using test::work_dir;
using test::write;

struct Result {
  int code;
  std::string out, err;
};

Result kinema_cli(const std::string& args) {
  const fs::path out = work_dir() / "stdout.txt", err = work_dir() / "stderr.txt";
  const std::string cmd = std::string(KINEMA_CLI) + " " + args + " >" + out.string() + " 2>" +
                          err.string();
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, read(out), read(err)};
}

std::string scene(const std::string& name) { return std::string(KINEMA_SCENES) + "/" + name; }

}  // namespace

TEST_CASE("help explains the command and every run option", "[cli]") {
  const Result top = kinema_cli("--help");
  CHECK(top.code == 0);
  CHECK(top.out.find("run") != std::string::npos);
  const Result run = kinema_cli("run --help");
  CHECK(run.code == 0);
  for (const char* option : {"--method", "--dt", "--steps", "--precision", "--out", "--every",
                             "--summary", "--isa", "--threads"}) {
    INFO(option);
    CHECK(run.out.find(option) != std::string::npos);
  }
}

TEST_CASE("the trajectory holds step 0, every K-th step and the last, bit for bit", "[cli]") {
  const fs::path csv = work_dir() / "traj.csv", summary = work_dir() / "summary.json";
  const Result r = kinema_cli("run " + scene("projectiles.json") + " --steps 20 --every 7 --out " +
                              csv.string() + " --summary " + summary.string());
  REQUIRE(r.code == 0);
  std::istringstream in(read(csv));
  std::string line;
  std::getline(in, line);
  CHECK(line == "step,t,body,px,py,pz,vx,vy,vz");
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::istringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) row.push_back(std::strtod(cell.c_str(), nullptr));
    rows.push_back(row);
  }
  REQUIRE(rows.size() == 4 * 4);  // steps 0, 7, 14, 20 for 4 bodies
  CHECK(rows[0][0] == 0);
  CHECK(rows[4][0] == 7);
  CHECK(rows[15][0] == 20);
  CHECK(rows[15][1] == 20 * double(float(1.0 / 60)));

  // The library, run directly, gives the very same floats.
  const Scene s = load_scene(scene("projectiles.json"));
  ParticleSet<float> b = make_particles<float>(s);
  Stepper<float> st(make_forces<float>(s), method_by_name(s.method));
  st.advance(b, float(s.dt), 20);
  for (std::size_t i = 0; i < 4; ++i) {
    const auto& row = rows[12 + i];
    CHECK(float(row[3]) == b.px()[i]);
    CHECK(float(row[4]) == b.py()[i]);
    CHECK(float(row[7]) == b.vy()[i]);
  }

  const auto j = nlohmann::json::parse(read(summary));
  for (const char* key : {"bodies", "steps", "method", "dt", "precision", "isa", "threads",
                          "wall_seconds", "body_steps_per_second", "energy_initial",
                          "energy_final", "finite"}) {
    INFO(key);
    CHECK(j.contains(key));
  }
  CHECK(j["bodies"] == 4);
  CHECK(j["steps"] == 20);
  CHECK(j["finite"] == true);
  CHECK(j["precision"] == "float");
  CHECK(j["energy_initial"].get<double>() ==
        Approx(energy(make_particles<float>(s), make_forces<float>(s)).total()));
  CHECK(r.out.find("body_steps_per_second") != std::string::npos);  // for people, too
}

TEST_CASE("rigid bodies add their columns to the trajectory", "[cli][rigid]") {
  const fs::path p = write("mixed.json", R"({"precision": "double", "steps": 4, "dt": 0.25,
      "particles": [{"position": [0,0,0], "velocity": [1,0,0]}],
      "rigid_bodies": [{"position": [5,0,0], "angular_momentum": [0,0,2], "inertia": [1,1,2]}]})");
  const fs::path csv = work_dir() / "mixed.csv";
  REQUIRE(kinema_cli("run " + p.string() + " --every 2 --quiet --out " + csv.string()).code == 0);
  std::istringstream in(read(csv));
  std::vector<std::string> lines_read;
  for (std::string line; std::getline(in, line);) lines_read.push_back(line);
  REQUIRE(lines_read.size() == 1 + 3 * 2);  // steps 0, 2, 4; one particle, one rigid body
  CHECK(lines_read[0] == "step,t,body,px,py,pz,vx,vy,vz,qw,qx,qy,qz,lx,ly,lz");
  CHECK(lines_read[5] == "4,1,0,1,0,0,1,0,0,,,,,,,");
  // Spin 1 rad/s about z for 1 s: q = (cos 0.5, 0, 0, sin 0.5).
  std::vector<double> cells;
  std::istringstream row(lines_read[6]);
  for (std::string cell; std::getline(row, cell, ',');) cells.push_back(std::stod(cell));
  REQUIRE(cells.size() == 16);
  CHECK(cells[2] == 1);  // numbered after the particles
  CHECK(cells[9] == Approx(std::cos(0.5)).epsilon(1e-4));
  CHECK(cells[12] == Approx(std::sin(0.5)).epsilon(1e-4));
  CHECK(cells[15] == 2);
}

TEST_CASE("options override the scene", "[cli]") {
  const fs::path summary = work_dir() / "override.json";
  const Result r = kinema_cli("run " + scene("damped_spring.json") +
                              " --method velocity_verlet --dt 0.02 --steps 50 --precision float"
                              " --isa scalar --threads 1 --quiet --summary " + summary.string());
  REQUIRE(r.code == 0);
  CHECK(r.out.empty());
  const auto j = nlohmann::json::parse(read(summary));
  CHECK(j["method"] == "velocity_verlet");
  CHECK(j["dt"] == 0.02);
  CHECK(j["steps"] == 50);
  CHECK(j["precision"] == "float");
  CHECK(j["isa"] == "scalar");
  CHECK(j["threads"] == 1);
}

TEST_CASE("run --rtol: dopri5 chooses its steps over the scene's duration and reports them", "[cli][adaptive]") {
  const fs::path summary = work_dir() / "adaptive.json";
  const Result r = kinema_cli("run " + scene("kepler_eccentric.json") + " --method dopri5 --rtol 1e-10 --atol 1e-10 -q --summary " +
                              summary.string());
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(read(summary));
  CHECK(j["t_final"] == 4.0);  // the last step lands on dt x steps
  CHECK(j["rtol"] == 1e-10);
  // The steps taken (accepted), not the scene's nominal 4000 of dt.
  const auto accepted = j["steps"].get<std::uint64_t>(), rejected = j["rejected_steps"].get<std::uint64_t>();
  CHECK_FALSE(j.contains("dt"));
  CHECK(accepted > 50);
  CHECK(accepted < 1000);  // far fewer than the scene's 4000 fixed steps
  // Six evaluations per attempt (the seventh is the next step's first), plus one for the
  // first step's size (one body: the run is one call).
  CHECK(j["force_evaluations"] == 6 * (accepted + rejected) + 1);
  CHECK(j["smallest_step"].get<double>() < j["largest_step"].get<double>());
  CHECK(std::abs(j["energy_final"].get<double>() - j["energy_initial"].get<double>()) < 1e-9);

  const Result fixed = kinema_cli("run " + scene("kepler_eccentric.json") + " -q --summary " + summary.string());
  REQUIRE(fixed.code == 0);
  CHECK(nlohmann::json::parse(read(summary))["force_evaluations"] == 4 * 4000);  // rk4, every run reports it
  CHECK_FALSE(nlohmann::json::parse(read(summary)).contains("rejected_steps"));

  const Result refused = kinema_cli("run " + scene("kepler_eccentric.json") + " --method rk4 --rtol 1e-6");
  CHECK(refused.code == 1);
  CHECK(refused.err.find("rtol and atol control the steps of a method with an embedded pair") != std::string::npos);
}

TEST_CASE("a state that blows up is reported, not hidden", "[cli]") {
  // 1e-150 from an attractor: a pull of 1e300 that overflows within the first step.
  const fs::path p = write("blowup.json", R"({"particles": [{"position": [1e-150,0,0]}],
      "forces": [{"type": "central", "mu": 1}], "steps": 3})");
  const Result r = kinema_cli("run " + p.string());
  CHECK(r.code == 3);
  CHECK(r.err.find("no longer finite") != std::string::npos);
}

namespace {

// Rows of a CSV file as maps from column name to text.
std::vector<std::map<std::string, std::string>> csv_rows(const fs::path& path) {
  std::istringstream in(read(path));
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  std::istringstream h(line);
  for (std::string cell; std::getline(h, cell, ',');) header.push_back(cell);
  std::vector<std::map<std::string, std::string>> rows;
  while (std::getline(in, line)) {
    std::istringstream cells(line);
    std::map<std::string, std::string> row;
    std::size_t i = 0;
    for (std::string cell; std::getline(cells, cell, ',') && i < header.size(); ++i) row[header[i]] = cell;
    rows.push_back(row);
  }
  return rows;
}

double number(const std::map<std::string, std::string>& row, const char* key) {
  return std::stod(row.at(key));
}

}  // namespace

TEST_CASE("chart: the CSV holds each point's true error and cost", "[cli][chart]") {
  const fs::path out = work_dir() / "chart_spring";
  const Result r = kinema_cli("chart " + scene("damped_spring.json") +
                              " --methods euler,rk4 --dts 0.02,0.01,0.005 --duration 2 --repeat 1 -q --out " +
                              out.string());
  REQUIRE(r.code == 0);
  const auto rows = csv_rows(out / "work_precision.csv");
  REQUIRE(rows.size() == 6);
  const Scene s = load_scene(scene("damped_spring.json"));
  const BodyStates exact = *analytic_states(s, 2);
  for (const auto& row : rows) {
    const Method& m = method_by_name(row.at("method"));
    const auto steps = std::uint64_t(number(row, "steps"));
    INFO(row.at("method") << " at " << steps << " steps");
    CHECK(number(row, "dt") * double(steps) == Approx(2));
    CHECK(row.at("analytic_reference") == "true");
    // The same number the library computes for that run.
    CHECK(number(row, "error") == Approx(state_error(simulate(s, m, steps, 2), exact)).epsilon(1e-12));
    CHECK(number(row, "force_evaluations") == double(steps * m.evaluations()));
    CHECK(number(row, "seconds_per_simulated_second") > 0);
  }
  // Steps sweep from the smallest: rk4's error grows 16-fold per doubling of h, euler's 2-fold.
  CHECK(number(rows[4], "error") / number(rows[3], "error") == Approx(16).epsilon(0.1));
  CHECK(number(rows[1], "error") / number(rows[0], "error") == Approx(2).epsilon(0.1));
  for (const char* file : {"work_precision.svg", "work_precision.png", "error_vs_step.svg", "error_vs_step.png"}) {
    INFO(file);
    CHECK(fs::file_size(out / file) > 1000);
  }
}

TEST_CASE("chart: an implicit method's cost counts its solves' iterations", "[cli][chart][implicit]") {
  const std::string text = R"({"precision": "double", "method": "ros2", "dt": 0.01, "steps": 10,
    "particles": [{"position": [-0.5, 0, 0], "velocity": [0, -1, 0], "mass": 1},
                  {"position": [0.6, 0, 0], "velocity": [0, 1, 0], "mass": 1}],
    "forces": [{"type": "springs", "pairs": [[0, 1, 1, 1e4, 0.5]]}]})";
  const fs::path path = write("stiff_pair.json", text);
  const fs::path out = work_dir() / "chart_implicit";
  const Result r = kinema_cli("chart " + path.string() + " --methods implicit_euler,ros2 --dts 0.01 --repeat 1 -q --out " +
                              out.string());
  REQUIRE(r.code == 0);
  const auto rows = csv_rows(out / "work_precision.csv");
  REQUIRE(rows.size() == 2);
  for (const auto& row : rows) {
    const Method& m = method_by_name(row.at("method"));
    INFO(m.name);
    World<double> world(parse_scene(text), m, on_calling_thread());
    world.advance(0.01, 10);
    const std::uint64_t iterations = world.particle_stepper().implicit_stats().iterations;
    CHECK(iterations >= 10 * m.rosenbrock.stages);
    CHECK(number(row, "force_evaluations") == double((10 * m.evaluations() + iterations) * 2));
  }
}

TEST_CASE("chart: fitted orders 1, 2, 2, 4, 1, 2, 3, 5, 6 on the eccentric orbit", "[cli][chart]") {
  const fs::path out = work_dir() / "chart_orbit";
  REQUIRE(kinema_cli("chart " + scene("kepler_eccentric.json") + " --repeat 1 -q --out " + out.string()).code == 0);
  const auto orders = csv_rows(out / "orders.csv");
  REQUIRE(orders.size() == 9);
  for (const auto& row : orders) {
    INFO(row.at("method"));
    REQUIRE_FALSE(row.at("fitted_order").empty());
    // dopri5 reads 5.19: at these steps its error still falls a little faster than h^5.
    CHECK(number(row, "fitted_order") == Approx(number(row, "nominal_order")).margin(0.2));
  }
  CHECK(read(out / "error_vs_step.gp").find("rk4 (fitted order 4.0") != std::string::npos);
}

TEST_CASE("stability: Euler spirals out, rk4 holds, Verlet stays bounded, and the measured limits", "[cli][stability]") {
  const fs::path out = work_dir() / "stability_orbit";
  // Ten orbits at h = T/100.
  const double period = 2 * std::numbers::pi;
  const Result r = kinema_cli("stability " + scene("kepler_circular.json") +
                              " --methods euler,rk4,velocity_verlet -q --dt " + std::to_string(period / 100) +
                              " --duration " + std::to_string(10 * period) + " --out " + out.string());
  REQUIRE(r.code == 0);
  std::map<std::string, double> last, worst;
  for (const auto& row : csv_rows(out / "energy.csv")) {
    const double e = std::abs(number(row, "relative_error"));
    last[row.at("method")] = e;
    worst[row.at("method")] = std::max(worst[row.at("method")], e);
  }
  CHECK(last["euler"] > 0.1);   // energy -1/(2r): r grew by more than 10%
  CHECK(worst["rk4"] < 1e-4);
  CHECK(worst["velocity_verlet"] < 1e-3);
  for (const auto& row : csv_rows(out / "trajectory.csv")) {
    const double radius = std::hypot(number(row, "x"), number(row, "y"));
    if (row.at("method") == "rk4") REQUIRE(radius == Approx(1).margin(1e-4));
  }
  const auto limits = csv_rows(out / "thresholds.csv");
  REQUIRE(limits.size() == 2);  // the explicit Runge-Kutta methods among those asked for
  CHECK(number(limits[0], "measured_threshold") == Approx(2).epsilon(1e-4));
  CHECK(number(limits[1], "measured_threshold") == Approx(2.785).epsilon(0.005));
  // Every boundary point lies on |R(z)| = 1: |1 + z| for Euler, the Taylor polynomial for rk4.
  for (const auto& row : csv_rows(out / "stability_region.csv")) {
    const std::complex<double> z(number(row, "re"), number(row, "im"));
    const std::complex<double> growth = row.at("method") == "euler"
        ? 1.0 + z : 1.0 + z + z * z / 2.0 + z * z * z / 6.0 + z * z * z * z / 24.0;
    REQUIRE(std::abs(growth) == Approx(1).epsilon(1e-9));
  }
  for (const char* file : {"energy.svg", "trajectory.svg", "stability_region.svg"}) CHECK(fs::file_size(out / file) > 1000);
}

TEST_CASE("chart runs no shell: names and paths are text, never commands", "[cli][chart]") {
  const fs::path marker = work_dir() / "pwned";
  const fs::path p = write("inject.json", "{\"name\": \"x`touch " + marker.string() + "`\", "
                           "\"particles\": [{\"position\": [1,0,0], \"velocity\": [0,1,0]}], "
                           "\"forces\": [{\"type\": \"central\", \"mu\": 1}], \"steps\": 50}");
  const std::string out = (work_dir() / "o$(touch ").string() + marker.string() + ")";
  CHECK(kinema_cli("chart " + p.string() + " --repeat 1 -q --out '" + out + "'").code == 0);
  CHECK_FALSE(fs::exists(marker));
}

TEST_CASE("run --method auto reports its choice and meets the tolerance", "[cli][auto]") {
  const fs::path summary = work_dir() / "auto.json";
  REQUIRE(kinema_cli("run " + scene("damped_spring.json") + " --method auto --tolerance 1e-6 -q --summary " +
                     summary.string()).code == 0);
  const auto j = nlohmann::json::parse(read(summary));
  CHECK(j["method"] == j["auto"]["method"]);
  CHECK(j["precision"] == j["auto"]["precision"]);
  if (j["auto"].contains("rtol")) {  // error-controlled steps
    CHECK(j["rtol"] == j["auto"]["rtol"]);
    CHECK(j["steps"].get<int>() > 0);
  } else {
    CHECK(j["steps"] == j["auto"]["steps"]);
  }
  CHECK(j["t_final"].get<double>() == Approx(20));
  CHECK(j["auto"]["estimated_error"].get<double>() <= 1e-6);
  CHECK(kinema_cli("run " + scene("damped_spring.json") + " --method auto").err.find("needs a tolerance") !=
        std::string::npos);
  // A loose tolerance lets a double scene run in float; a precision the command line names is kept.
  const auto precision_of = [&](const std::string& options) {
    REQUIRE(kinema_cli("run " + scene("damped_spring.json") + " --method auto --tolerance 1e-4 -q --summary " +
                       summary.string() + options).code == 0);
    const auto run = nlohmann::json::parse(read(summary));
    CHECK(run["precision"] == run["auto"]["precision"]);
    return run["precision"].get<std::string>();
  };
  CHECK(precision_of(" --precision double") == "double");
  CHECK(precision_of(" --precision float") == "float");
}

TEST_CASE("run: a scene's tolerance with another method is refused, or noted when --method names it",
          "[cli][auto]") {
  fs::path file = write("tolerance_scene.json", R"({"method": "rk4", "tolerance": 1e-6, "steps": 2, "particles": [{"position": [1, 0, 0]}]})");
  const Result own = kinema_cli("run " + file.string() + " -q");
  CHECK(own.code == 1);
  CHECK(own.err.find("tolerance: bounds the error of method auto's choice; the scene's method is rk4") !=
        std::string::npos);
  // An auto scene run at a named method keeps its tolerance for auto runs.
  file = write("tolerance_scene.json", R"({"method": "auto", "tolerance": 1e-6, "steps": 2, "particles": [{"position": [1, 0, 0]}]})");
  const Result named = kinema_cli("run " + file.string() + " --method euler");
  CHECK(named.code == 0);
  CHECK(named.err.find("kinema: note: the scene's tolerance bounds method auto's choice; unused with --method euler") !=
        std::string::npos);
  CHECK(kinema_cli("run " + file.string() + " --method euler -q").err.empty());
  CHECK(kinema_cli("run " + file.string() + " -q").code == 0);
}

namespace {

// The value a printed summary shows for `key` (the text after the key, unit included).
std::string printed(const std::string& out, const std::string& key) {
  std::istringstream in(out);
  for (std::string line; std::getline(in, line);) {
    std::istringstream words(line);
    std::string first;
    words >> first;
    if (first != key) continue;
    std::string rest;
    std::getline(words >> std::ws, rest);
    return rest;
  }
  return "(no " + key + ")";
}

// A JSON value as the printed summary shows it.
std::string shown(const nlohmann::json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

}  // namespace

TEST_CASE("run under error control: the summary's steps and throughput are the stepper's own", "[cli][adaptive]") {
  // 3000 bodies in float, a single advance_to call over the run (a call covers 2^26 body-steps'
  // worth of dt; this run has 3000 x 600), so the library run below is the very same call.
  const fs::path path = write("adaptive_field.json", R"({"precision": "float", "method": "bs3", "dt": 0.016666666666666666,
      "steps": 600, "generate": {"count": 3000, "seed": 3, "position_min": [-10,-10,-10], "position_max": [10,10,10],
                                 "velocity_min": [-1,-1,-1], "velocity_max": [1,1,1]},
      "forces": [{"type": "gravity", "g": [0,-9.81,0]}, {"type": "linear_drag", "k": 0.5},
                 {"type": "spring", "anchor": [0,0,0], "k": 2}]})");
  const fs::path summary = work_dir() / "adaptive_field_summary.json";
  const Result r = kinema_cli("run " + path.string() + " --rtol 1e-6 --summary " + summary.string());
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(read(summary));

  // The library, as the program calls it: error control capped at the largest stable step
  // estimated (in double, on a sample of 1024 bodies) at the start.
  const Scene s = load_scene(path);
  const StiffnessEstimate e = estimate_stiffness(make_particles<double>(sample_bodies(s, 1024)), make_forces<double>(s), 0, 40);
  Tolerances tolerances;
  tolerances.rtol = tolerances.atol = 1e-6;
  tolerances.max_step = largest_stable_step(bs3, e);
  ParticleSet<float> bodies = make_particles<float>(s);
  Stepper<float> stepper(make_forces<float>(s), bs3);
  const AdaptiveStats a = stepper.advance_to(bodies, s.dt * double(s.steps), tolerances);

  CHECK(j["steps"] == a.accepted);
  CHECK(j["rejected_steps"] == a.rejected);
  CHECK(j["force_evaluations"] == a.evaluations);
  CHECK(a.accepted < s.steps);  // not the nominal steps, so the checks below mean something
  CHECK_FALSE(j.contains("dt"));  // no nominal step presented as taken
  CHECK(j["t_final"] == 10);
  CHECK(j["mean_step"].get<double>() == Approx(10.0 / double(a.accepted)).epsilon(1e-8));
  CHECK(j["smallest_step"].get<double>() <= j["mean_step"].get<double>());
  CHECK(j["largest_step"].get<double>() >= j["mean_step"].get<double>());
  // Throughput from the body-steps taken, each figure to four digits.
  const double body_steps = 3000.0 * double(a.accepted);
  CHECK(j["body_steps_per_second"].get<double>() == Approx(body_steps / j["wall_seconds"].get<double>()).epsilon(1e-3));
  CHECK(j["units"]["mean_step"] == "s");
  CHECK(j["units"]["stiffness"] == "1/s");
  CHECK(j["units"]["largest_stable_step"] == "s");
  // What people read is what the file holds.
  for (const char* key : {"steps", "rejected_steps", "body_steps_per_second", "wall_seconds", "rtol", "force_evaluations"}) {
    INFO(key);
    CHECK(printed(r.out, key) == shown(j[key]));
  }
  CHECK(printed(r.out, "mean_step") == shown(j["mean_step"]) + " s");
  CHECK(printed(r.out, "stiffness") == shown(j["stiffness"]) + " 1/s");
}

TEST_CASE("run: fixed steps are shown as the precision holds them, numbers without binary noise", "[cli]") {
  const fs::path summary = work_dir() / "float_steps_summary.json";
  // dt 1/60 in float is 0.016666668: 600 of them end at 10.0000005, not at 10.
  const fs::path path = write("float_steps.json", R"({"precision": "float", "dt": 0.016666666666666666, "steps": 600,
      "particles": [{"position": [1,0,0]}], "forces": [{"type": "spring", "anchor": [0,0,0], "k": 2}]})");
  const Result r = kinema_cli("run " + path.string() + " --summary " + summary.string());
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(read(summary));
  CHECK(j["steps"] == 600);
  CHECK(j["dt"].dump() == "0.016666668");
  CHECK(float(j["dt"].get<double>()) == float(1.0 / 60));
  CHECK(j["t_final"].dump() == "10.0000005");
  CHECK(j["t_final"].get<double>() == Approx(600 * double(float(1.0 / 60))).epsilon(1e-8));
  CHECK(j["body_steps_per_second"].get<double>() == Approx(600 / j["wall_seconds"].get<double>()).epsilon(1e-3));
  CHECK(printed(r.out, "dt") == "0.016666668 s");
  CHECK(printed(r.out, "t_final") == "10.0000005 s");
  CHECK(printed(r.out, "stiffness") == shown(j["stiffness"]) + " 1/s");
  CHECK(printed(r.out, "largest_stable_step") == shown(j["largest_stable_step"]) + " s");
  // Measured figures to four significant digits.
  for (const char* key : {"wall_seconds", "body_steps_per_second", "stiffness", "largest_stable_step"}) {
    INFO(key << " " << j[key].dump());
    const double v = j[key].get<double>();
    char text[40];
    std::snprintf(text, sizeof text, "%.4g", v);
    CHECK(std::strtod(text, nullptr) == v);
  }
  // rtol as the user wrote it; a double run's time without the product's last bits.
  const Result adaptive = kinema_cli("run " + scene("kepler_eccentric.json") + " --method dopri5 --rtol 1e-6 -q --summary " + summary.string());
  REQUIRE(adaptive.code == 0);
  CHECK(nlohmann::json::parse(read(summary))["rtol"].dump() == "1e-06");
  REQUIRE(kinema_cli("run " + scene("kepler_circular.json") + " -q --summary " + summary.string()).code == 0);
  CHECK(nlohmann::json::parse(read(summary))["t_final"].dump() == "62.83");  // 6283 x 0.01
}

TEST_CASE("run: workers_used comes with what the stepper measured", "[cli]") {
  const fs::path summary = work_dir() / "workers_summary.json";
  const fs::path path = write("workers.json", R"({"steps": 200,
      "generate": {"count": 20000, "position_min": [0,0,0], "position_max": [1,1,1]}, "forces": [{"type": "linear_drag", "k": 1}]})");
  for (const char* threads : {"1", "2"}) {
    INFO("threads " << threads);
    REQUIRE(kinema_cli("run " + path.string() + " -q --threads " + threads + " --summary " + summary.string()).code == 0);
    const auto j = nlohmann::json::parse(read(summary));
    const std::string note = j["workers_note"];
    const unsigned used = j["workers_used"];
    if (j["threads"] == 1) {
      CHECK(used == 1);
      CHECK(note.find("one worker takes every call") != std::string::npos);
    } else if (used == 0) {
      CHECK(note.find("the calling thread alone was as fast as") != std::string::npos);
      CHECK(note.find("(100 calls of") != std::string::npos);  // steps / 100 per call
    } else {
      CHECK(note.find(std::to_string(used) + " of " + j["threads"].dump() + " workers were fastest") != std::string::npos);
    }
    CHECK(note.find("N-body") == std::string::npos);
  }
  // N-body passes take every worker whatever the count the timings favour: the note says so.
  REQUIRE(kinema_cli("run " + scene("plummer_cluster.json") + " -q --steps 3 --threads 2 --summary " +
                     summary.string()).code == 0);
  const std::string note = nlohmann::json::parse(read(summary))["workers_note"];
  CHECK(note.find("the N-body passes ran on all 2 workers") != std::string::npos);
}

TEST_CASE("run: the summary's path is the one the bodies took", "[cli]") {
  const fs::path summary = work_dir() / "path_summary.json";
  const auto path_of = [&](const std::string& scene_name, const std::string& options) {
    REQUIRE(kinema_cli("run " + scene(scene_name) + " -q --steps 2 --summary " + summary.string() + options).code == 0);
    return nlohmann::json::parse(read(summary))["path"].get<std::string>();
  };
  CHECK(path_of("kepler_circular.json", "") == "fused");
  CHECK(path_of("plummer_cluster.json", "") == "staged");
  CHECK(path_of("cloth.json", " --method implicit_euler") == "implicit");
  CHECK(path_of("spinning_debris.json", "") == "fused");  // rigid bodies, local terms
  CHECK(path_of("box_chain.json", "") == "rigid");          // body springs: the rigid path
}

TEST_CASE("kinema --version prints the library's version", "[cli]") {
  const Result r = kinema_cli("--version");
  CHECK(r.code == 0);
  CHECK(r.out == std::string("kinema ") + KINEMA_VERSION_STRING + "\n");
  CHECK(r.out == "kinema " + std::to_string(KINEMA_VERSION_MAJOR) + "." + std::to_string(KINEMA_VERSION_MINOR) + "." +
                     std::to_string(KINEMA_VERSION_PATCH) + "\n");
  CHECK(kinema_cli("--help").out.find("--version") != std::string::npos);
}

TEST_CASE("a usage error points to the help of the command it is in", "[cli]") {
  CHECK(kinema_cli("run").err.find("scene is required (see kinema run --help)") != std::string::npos);
  CHECK(kinema_cli("run " + scene("damped_spring.json") + " --steps x").err.find("(see kinema run --help)") != std::string::npos);
  CHECK(kinema_cli("stress --bodies 0").err.find("(see kinema stress --help)") != std::string::npos);
  CHECK(kinema_cli("chart").err.find("(see kinema chart --help)") != std::string::npos);
  CHECK(kinema_cli("stability").err.find("(see kinema stability --help)") != std::string::npos);
  CHECK(kinema_cli("").err.find("(see kinema --help)") != std::string::npos);
  const Result unknown = kinema_cli("bogus");
  CHECK(unknown.code == 2);
  CHECK(unknown.err.find("unknown command 'bogus': run, chart, stability or stress (see kinema --help)") != std::string::npos);
}

TEST_CASE("run -q: the stable-step warning still prints", "[cli]") {
  // Euler on v' = -30 v at h = 0.1: past its largest stable step (2/30), growing twofold a step.
  const fs::path path = write("unstable.json", R"({"precision": "double", "method": "euler", "dt": 0.1, "steps": 20,
      "particles": [{"position": [0,0,0], "velocity": [1,0,0]}], "forces": [{"type": "linear_drag", "k": 30}]})");
  const Result finite = kinema_cli("run " + path.string() + " -q");
  CHECK(finite.code == 0);  // 2^20: still finite
  CHECK(finite.out.empty());
  CHECK(finite.err.find("kinema: warning: dt 0.1 is past the largest stable step of euler") != std::string::npos);
  const Result blown = kinema_cli("run " + path.string() + " -q --steps 2000");
  CHECK(blown.code == 3);
  CHECK(blown.err.find("kinema: warning: dt 0.1 is past the largest stable step") != std::string::npos);
  CHECK(blown.err.find("no longer finite") != std::string::npos);
  // A stable step: -q is silent.
  const Result stable = kinema_cli("run " + path.string() + " -q --dt 0.01");
  CHECK(stable.code == 0);
  CHECK(stable.err.empty());
}

TEST_CASE("run --strict: steps far past the stable one, and an estimate that overflows", "[cli]") {
  // One body under an attractor of mu = 1e100 at r = 1: |lambda| = 1e50 /s, dt 0.01. The step's
  // 2 x 2 matrix has entries past 1e150, whose determinant overflowed (no warning before).
  const auto attractor = [](const char* mu) {
    return write(std::string("attractor") + mu + ".json",
                 std::string(R"({"precision": "double", "method": "rk4", "dt": 0.01, "steps": 100,
      "particles": [{"position": [1, 0, 0], "velocity": [0, 1, 0]}],
      "forces": [{"type": "central", "center": [0, 0, 0], "mu": )") + mu + "}]}");
  };
  const fs::path summary = work_dir() / "strict.json";
  const Result far = kinema_cli("run " + attractor("1e100").string() + " -q --strict --summary " + summary.string());
  CHECK(far.code == 1);
  CHECK(far.err.find("past the largest stable step of rk4 on this scene, 2.83e-50") != std::string::npos);
  CHECK(far.err.find("grows more than 1e300-fold over the run (--strict)") != std::string::npos);
  const auto j = nlohmann::json::parse(read(summary));  // the refusal's summary has the estimate
  CHECK(j["stiffness"].get<double>() == Approx(1e50).epsilon(1e-3));
  CHECK(j["largest_stable_step"].get<double>() == Approx(2.828e-50).epsilon(1e-3));
  // Two bodies at one point under unsoftened N-body gravity: a damping mode of 6e164 /s,
  // whose step's diagonal overflows to NaN (it read as a growth of 1 before).
  const fs::path twins = write("twins.json", R"({"precision": "double", "method": "rk4", "dt": 0.01, "steps": 100,
      "particles": [{"position": [0, 0, 0]}, {"position": [0, 0, 0]}, {"position": [1, 0, 0]}],
      "forces": [{"type": "nbody", "G": 1}]})");
  CHECK(kinema_cli("run " + twins.string() + " -q --strict").err.find("(damping at |lambda| = 5.766e+164 /s) grows more than") !=
        std::string::npos);
  // At mu = 1e150 the estimate itself overflows: a warning, and --strict refuses.
  const fs::path huge = attractor("1e150");
  const Result warned = kinema_cli("run " + huge.string() + " -q");
  CHECK(warned.code == 0);
  CHECK(warned.err.find("kinema: warning: the stiffness estimate overflows double on this scene") != std::string::npos);
  const Result refused = kinema_cli("run " + huge.string() + " -q --strict --summary " + summary.string());
  CHECK(refused.code == 1);
  const auto unbounded = nlohmann::json::parse(read(summary));  // no estimate, no stable step
  CHECK(unbounded["stiffness"].is_null());
  CHECK_FALSE(unbounded.contains("largest_stable_step"));
  CHECK(refused.err.find("dt is not checked against the largest stable step (--strict)") != std::string::npos);
}

TEST_CASE("run: an implicit method on a scene without springs says its steps are explicit", "[cli][implicit]") {
  const Result orbit = kinema_cli("run " + scene("kepler_circular.json") + " --method ros2 --steps 3");
  CHECK(orbit.code == 0);
  CHECK(orbit.err.find("kinema: note: ros2 takes spring networks implicitly and this scene has none: every force is "
                       "explicit, each step its explicit part's\n") != std::string::npos);
  const Result euler = kinema_cli("run " + scene("kepler_circular.json") + " --method implicit_euler --steps 3");
  CHECK(euler.err.find("each step its explicit part's (symplectic Euler's, to rounding)") != std::string::npos);
  CHECK(kinema_cli("run " + scene("kepler_circular.json") + " --method ros2 --steps 3 -q").err.empty());
  // A scene with springs: no note.
  CHECK(kinema_cli("run " + scene("cloth.json") + " --method implicit_euler --steps 2").err.find("note:") ==
        std::string::npos);
}

TEST_CASE("chart and stability count an implicit solve's overflow as a blow-up", "[cli][implicit]") {
  // An anchored spring (explicit under ros2) at h omega = 4 blows up; with a spring pair in
  // the scene the solve's sums overflow double first. Both commands once stopped there.
  const fs::path p = write("anchored_pair.json", R"({"precision": "double", "dt": 0.05, "steps": 400,
      "particles": [{"position": [1,0,0]}, {"position": [2,0,0]}],
      "forces": [{"type": "spring", "anchor": [0,0,0], "k": 400}, {"type": "springs", "pairs": [[0,1,1,1,0]]}]})");
  const fs::path chart_out = work_dir() / "overflow_chart", stability_out = work_dir() / "overflow_stability";
  const Result chart = kinema_cli("chart " + p.string() + " --methods ros2,rk4 --dts 0.2,0.1,0.01 --duration 20 "
                                  "--repeat 1 -q --out " + chart_out.string());
  CHECK(chart.code == 0);
  CHECK(chart.err.empty());
  const std::string csv = read(chart_out / "work_precision.csv");
  CHECK(csv.find("ros2,2,0.20000000000000001,100,inf,,") != std::string::npos);  // not timed: an empty cell
  CHECK(csv.find("nan") == std::string::npos);
  const Result stability = kinema_cli("stability " + p.string() + " --methods euler,ros2 --dt 0.2 --duration 20 -q "
                                      "--out " + stability_out.string());
  CHECK(stability.code == 0);
  CHECK(stability.err.empty());
}

TEST_CASE("run: a rigid-body term in a scene without rigid bodies is noted as doing nothing", "[cli]") {
  const fs::path p = write("idle_torque.json", R"({"particles": [{"position": [1,0,0]}], "steps": 3,
      "forces": [{"type": "gravity", "g": [0,-1,0]}, {"type": "torque", "torque": [1,0,0]}]})");
  const Result r = kinema_cli("run " + p.string());
  CHECK(r.code == 0);
  CHECK(r.err.find("kinema: note: torque acts on rigid bodies only, and this scene has none: it does nothing") !=
        std::string::npos);
  CHECK(r.err.find("gravity") == std::string::npos);
  CHECK(kinema_cli("run " + p.string() + " -q").err.empty());
}

TEST_CASE("run: a state that blew up gets its error, not an energy warning", "[cli]") {
  const Result r = kinema_cli("run " + scene("stiff_pair.json") + " -q --steps 20 --method rk6");
  CHECK(r.code == 3);
  CHECK(r.err.find("no longer finite") != std::string::npos);
  CHECK(r.err.find("energy") == std::string::npos);
}

TEST_CASE("run --method auto: one readable line for its choice, costs in force evaluations", "[cli][auto]") {
  const fs::path summary = work_dir() / "auto_line.json";
  const Result r = kinema_cli("run " + scene("kepler_eccentric.json") + " --method auto --tolerance 1e-6 --summary " +
                              summary.string());
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(read(summary));
  const std::string line = printed(r.out, "auto");
  CHECK(line == j["auto"]["choice"]);
  CHECK(line.find('{') == std::string::npos);  // no JSON on stdout
  CHECK(line.rfind(j["method"].get<std::string>(), 0) == 0);  // starts with the method
  CHECK(line.find(j["auto"]["force_evaluations"].dump() + " force evaluations, the fewest") != std::string::npos);
  CHECK(line.find("under 1e-06 over 4 s") != std::string::npos);
  if (j["auto"].contains("rtol")) {
    CHECK(line.find("with error control (rtol = atol = " + j["auto"]["rtol"].dump()) != std::string::npos);
  } else {
    CHECK(line.find("(" + j["auto"]["steps"].dump() + " steps)") != std::string::npos);
  }
  CHECK_FALSE(j["auto"].contains("reason"));
  // Every candidate's cost is its steps times the method's evaluations per step.
  REQUIRE_FALSE(j["auto"]["candidates"].empty());
  for (const auto& c : j["auto"]["candidates"]) {
    CHECK(c["force_evaluations"] == c["steps"].get<std::uint64_t>() * std::uint64_t(method_by_name(c["method"].get<std::string>()).evaluations()));
  }
}

TEST_CASE("stability: a table of predicted and measured steps, and where an orbit breaks the linear bound", "[cli][stability]") {
  const fs::path out = work_dir() / "stability_table";
  const Result orbit = kinema_cli("stability " + scene("kepler_circular.json") + " --methods euler,rk4 --out " + out.string());
  REQUIRE(orbit.code == 0);
  const auto limits = csv_rows(out / "step_limits.csv");
  REQUIRE(limits.size() == 2);
  CHECK(orbit.out.find("  method              predicted   measured   measured/predicted\n") != std::string::npos);
  for (const auto& row : limits) {
    INFO(row.at("method"));
    const double predicted = number(row, "predicted_step"), measured = number(row, "measured_step");
    char line[160];
    std::snprintf(line, sizeof line, "  %-18s %10.4g %10.4g   %.2f *\n", row.at("method").c_str(), predicted, measured,
                  measured / predicted);
    CHECK(measured < 0.8 * predicted);  // the orbit breaks the bound for both
    CHECK(orbit.out.find(line) != std::string::npos);
  }
  CHECK(orbit.out.find("(|lambda| = 1.414 /s)") != std::string::npos);  // sqrt(2): the radial mode at r = 1
  CHECK(orbit.out.find("On an orbit that mode is not the\n  orbit's turning") != std::string::npos);

  // A linear scene: the prediction holds, and there is nothing to explain.
  const Result spring = kinema_cli("stability " + scene("damped_spring.json") + " --methods rk4,velocity_verlet --out " + out.string());
  REQUIRE(spring.code == 0);
  for (const auto& row : csv_rows(out / "step_limits.csv")) {
    CHECK(number(row, "measured_step") == Approx(number(row, "predicted_step")).epsilon(0.05));
  }
  CHECK(spring.out.find(" *\n") == std::string::npos);
  CHECK(spring.out.find("breaks the linear bound") == std::string::npos);
  for (const auto& row : csv_rows(out / "step_limits.csv")) CHECK(row.at("capped_by_duration") == "0");

  // A run shorter than the limits: every step under the duration holds, which bounds the
  // limit from below and says nothing of the linear bound (it read as broken, 0.34x).
  const Result brief = kinema_cli("stability " + scene("damped_spring.json") + " --methods rk4 --duration 0.5 --out " + out.string());
  REQUIRE(brief.code == 0);
  const auto capped = csv_rows(out / "step_limits.csv");
  REQUIRE(capped.size() == 1);
  CHECK(capped[0].at("capped_by_duration") == "1");
  CHECK(number(capped[0], "measured_step") < 0.5);
  CHECK(number(capped[0], "measured_step") > 0.49);
  CHECK(brief.out.find(" >= 0.49") != std::string::npos);
  CHECK(brief.out.find("give a longer --duration") != std::string::npos);
  CHECK(brief.out.find("breaks the linear bound") == std::string::npos);
  // Even where the prediction is thousands of times the run (it read 0 and broken).
  const Result briefer = kinema_cli("stability " + scene("damped_spring.json") +
                                    " --methods rk4 --dt 0.0001 --duration 0.0003 --out " + out.string());
  REQUIRE(briefer.code == 0);
  const auto bound = csv_rows(out / "step_limits.csv");
  REQUIRE(bound.size() == 1);
  CHECK(bound[0].at("capped_by_duration") == "1");
  CHECK(number(bound[0], "measured_step") > 0.00029);
  CHECK(briefer.out.find("breaks the linear bound") == std::string::npos);

  // A spring network with every method by default: the table says how to draw the implicit
  // ones, which the default leaves out; named methods get no such line.
  const std::string pair = "stability " + scene("stiff_pair.json") + " --duration 0.02 --out " + out.string();
  const Result all = kinema_cli(pair);
  REQUIRE(all.code == 0);
  CHECK(all.out.find("implicit_euler and ros2 (springs implicit, predicted from the other forces) are drawn when named in "
                     "--methods") != std::string::npos);
  CHECK(csv_rows(out / "step_limits.csv").size() == 9);
  const Result named = kinema_cli(pair + " --methods rk4,implicit_euler");
  REQUIRE(named.code == 0);
  CHECK(named.out.find("are drawn when named") == std::string::npos);
  CHECK(named.out.find("  implicit_euler ") != std::string::npos);
}

// The charts' files and styles, as the chart and stability commands write them.
namespace {

// Each plot item with a title in a gnuplot script kinema wrote: the method the title names
// (its first word) and the item's colour and dash ("lc rgb '#rrggbb' dt D ... title 'NAME...").
std::vector<std::pair<std::string, std::string>> titled_styles(const fs::path& gp) {
  std::vector<std::pair<std::string, std::string>> out;
  const std::string text = read(gp);
  for (std::size_t at = text.find("lc rgb '"); at != std::string::npos; at = text.find("lc rgb '", at + 1)) {
    const std::size_t dash = text.find(" dt ", at), title = text.find(" title '", at);
    const std::size_t item_end = text.find_first_of(",\n", at);
    if (dash > item_end || title > item_end) continue;  // no dash or no title: not a method
    const std::string colour = text.substr(at + 8, 7);
    const std::string dash_type = text.substr(dash + 4, text.find(' ', dash + 4) - dash - 4);
    const std::size_t name = title + 8;
    out.emplace_back(text.substr(name, text.find_first_of(" ,'", name) - name), colour + " dt " + dash_type);
  }
  return out;
}

}  // namespace

TEST_CASE("chart lists every file it wrote, the error_vs_evaluations charts among them", "[cli][chart]") {
  const fs::path out = work_dir() / "chart_listed";
  const Result r = kinema_cli("chart " + scene("damped_spring.json") +
                              " --methods euler,rk4 --dts 0.02,0.01 --duration 2 --repeat 1 --out " + out.string());
  REQUIRE(r.code == 0);
  const std::size_t list = r.out.find("wrote in");
  REQUIRE(list != std::string::npos);
  std::istringstream words(r.out.substr(r.out.find('\n', list)));
  std::map<std::string, int> listed;
  for (std::string w; words >> w;) ++listed[w];
  std::map<std::string, int> present;
  for (const auto& entry : fs::directory_iterator(out)) ++present[entry.path().filename().string()];
  CHECK(listed == present);
  for (const char* file : {"error_vs_evaluations.svg", "error_vs_evaluations.png", "error_vs_evaluations.gp",
                           "work_precision.csv", "orders.csv", "points_rk4.dat"}) {
    INFO(file);
    CHECK(listed.count(file) == 1);
  }
}

TEST_CASE("each method has one colour and dash in every chart, no two methods the same", "[cli][chart][stability]") {
  const fs::path charts = work_dir() / "styles_chart", stability = work_dir() / "styles_stability";
  REQUIRE(kinema_cli("chart " + scene("kepler_eccentric.json") + " --dts 0.004,0.002 --repeat 1 -q --out " +
                     charts.string()).code == 0);
  REQUIRE(kinema_cli("stability " + scene("kepler_circular.json") + " -q --out " + stability.string()).code == 0);
  std::map<std::string, std::string> style_of;  // method -> colour and dash
  for (const fs::path& gp : {charts / "work_precision.gp", charts / "error_vs_step.gp",
                             charts / "error_vs_evaluations.gp", stability / "energy.gp",
                             stability / "trajectory.gp", stability / "stability_region.gp"}) {
    const auto styles = titled_styles(gp);
    CHECK(styles.size() >= 7);  // the Runge-Kutta methods at least
    for (const auto& [method, style] : styles) {
      INFO(gp.filename().string() << ": " << method);
      CHECK(style_of.emplace(method, style).first->second == style);
    }
  }
  REQUIRE(style_of.size() == 9);
  std::map<std::string, std::string> method_of;  // colour and dash -> method
  for (const auto& [method, style] : style_of) {
    const auto [first, unique] = method_of.emplace(style, method);
    INFO(method << " and " << first->second << " share " << style);
    CHECK(unique);
  }
}

TEST_CASE("run writes the scene's events to events.csv beside the trajectory; a stop event ends the run there",
          "[cli][events]") {
  // Body 0 lands at (3 + sqrt(9 + 2 g 10)) / g, body 1 at (-2 + sqrt(4 + 2 g 30)) / g.
  const double g = 9.81, first = (3 + std::sqrt(9 + 2 * g * 10)) / g, second = (-2 + std::sqrt(4 + 2 * g * 30)) / g;
  // Fixed steps, then error control (dopri5's steps, exact on a parabola); rigid bodies
  // turning as they fall, on fixed steps (the command takes rtol and atol for particles).
  const auto drop = [](const std::string& action, const std::string& control, const std::string& kind) {
    const std::string turning = kind == "rigid_bodies" ? R"(, "angular_momentum": [0.3, 1, -2], "inertia": [1, 2, 3])" : "";
    return R"({"name": "drop", "precision": "double", "dt": 0.05, "steps": 100, )" + control + R"(
      ")" + kind + R"(": [{"position": [0, 10, 0], "velocity": [1, 3, 0])" + turning + R"(},
                          {"position": [2, 30, 0], "velocity": [0, -2, 0])" + turning + R"(}],
      "forces": [{"type": "gravity", "g": [0, -9.81, 0]}],
      "events": [{"type": "plane", "normal": [0, 1, 0], "direction": "down", "action": ")" + action + R"("},
                 {"type": "speed", "speed": 1000, "direction": "up"}]})";
  };
  const fs::path dir = work_dir() / "events";
  fs::create_directories(dir);
  const fs::path csv = dir / "traj.csv", summary = dir / "summary.json", events = dir / "events.csv";
  const std::string adaptive = R"("method": "dopri5", "rtol": 1e-9, "atol": 1e-9,)";
  for (const auto& [kind, control] : {std::pair<std::string, std::string>{"particles", ""}, {"particles", adaptive},
                                      {"rigid_bodies", ""}}) {
    for (const std::string action : {"record", "stop"}) {
      INFO(kind << " " << action << " " << control);
      const fs::path file = write("drop_" + action + ".json", drop(action, control, kind));
      REQUIRE(kinema_cli("run " + file.string() + " -q --out " + csv.string() + " --summary " + summary.string()).code == 0);
      std::istringstream rows(read(events));
      std::string line;
      std::getline(rows, line);
      CHECK(line == "time,body,event,type,px,py,pz,vx,vy,vz");
      std::vector<double> times, vy;  // vy: column 9, the state to double's digits (it had 9)
      while (std::getline(rows, line)) {
        CHECK(line.find(",plane,") != std::string::npos);
        times.push_back(std::stod(line));
        std::size_t at = 0;
        for (int comma = 0; comma < 8; ++comma) at = line.find(',', at) + 1;
        vy.push_back(std::stod(line.substr(at)));
      }
      for (std::size_t k = 0; k < times.size(); ++k) {  // each body's vy at its landing: 3 - g t, -2 - g t
        CHECK(std::abs(vy[k] - ((k == 0 ? 3 : -2) - g * times[k])) < 1e-12);
      }
      const auto j = nlohmann::json::parse(read(summary));
      CHECK(j["complete"] == true);
      if (action == "record") {
        REQUIRE(times.size() == 2);
        CHECK(std::abs(times[0] - first) < 1e-12);
        CHECK(std::abs(times[1] - second) < 1e-12);
        CHECK(j["events"] == 2);
        CHECK(j["t_final"].get<double>() == Approx(5));
      } else {
        REQUIRE(times.size() == 1);
        CHECK(j["events"] == 1);
        CHECK(j["stopped_by_event"] == "events[0] (plane), body 0");
        CHECK(std::abs(j["t_final"].get<double>() - first) < 1e-12);
      }
    }
  }
  const Result bad = kinema_cli("run " + write("bad_event.json", R"({"particles": [{"position": [0, 1, 0]}],
      "events": [{"type": "plane", "normal": [0, 0, 0]}]})").string());
  CHECK(bad.code != 0);
  CHECK(bad.err.find("events[0].normal") != std::string::npos);
}

TEST_CASE("run: the cloth at 60 Hz blows up under rk4, which names the implicit methods, and holds under them",
          "[cli][implicit]") {
  const std::string at_60_hz = " -q --dt 0.016666666666666666 --steps 8";
  const Result explicit_run = kinema_cli("run " + scene("cloth.json") + at_60_hz + " --method rk4");
  CHECK(explicit_run.code == 3);
  CHECK(explicit_run.err.find("past the largest stable step of rk4") != std::string::npos);
  CHECK(explicit_run.err.find("--method implicit_euler or ros2") != std::string::npos);
  const fs::path summary = work_dir() / "implicit_summary.json";
  for (const std::string method : {"implicit_euler", "ros2"}) {
    const Result r = kinema_cli("run " + scene("cloth.json") + at_60_hz + " --method " + method + " --summary " +
                                summary.string());
    CHECK(r.code == 0);
    CHECK(r.err.empty());  // no warning: the method holds at this step
    const auto j = nlohmann::json::parse(read(summary));
    CHECK(j["linear_solves"] == (method == "ros2" ? 16 : 8));
    CHECK(j["cg_iterations"].get<int>() >= j["linear_solves"].get<int>());  // a solve takes one at least
    CHECK(j["cg_unconverged"] == 0);
    CHECK(j["finite"] == true);
  }
  // A looser solve: fewer iterations, other bits.
  const auto crc = [&](const std::string& options) {
    REQUIRE(kinema_cli("run " + scene("cloth.json") + at_60_hz + " --method ros2 --summary " + summary.string() +
                       options).code == 0);
    const auto j = nlohmann::json::parse(read(summary));
    return std::pair(j["state_crc32c"].get<std::string>(), j["cg_iterations"].get<int>());
  };
  const auto tight = crc(""), loose = crc(" --implicit-tolerance 1e-2");
  CHECK(loose.first != tight.first);
  CHECK(loose.second < tight.second);
  CHECK(crc(" --implicit-tolerance 1e-5 --implicit-iterations 5").second == 5 * 16);  // every solve capped
  // The 4096-body cloth takes multigrid by default: naming it changes nothing, Jacobi's solves
  // take more iterations to other bits.
  const auto jacobi = crc(" --implicit-preconditioner jacobi");
  CHECK(crc(" --implicit-preconditioner multigrid") == tight);
  CHECK(jacobi.first != tight.first);
  CHECK(jacobi.second > 3 * tight.second);
  CHECK(kinema_cli("run " + scene("cloth.json") + " -q --steps 1 --implicit-preconditioner ilu").code != 0);
  // What an implicit method steps explicitly can still break it: a stiff drag is euler's to it.
  const fs::path drag = write("stiff_drag.json", R"({"precision": "double", "method": "implicit_euler", "dt": 0.01,
      "steps": 100, "particles": [{"position": [0,0,0], "velocity": [1,0,0]}], "forces": [{"type": "linear_drag", "k": 300}]})");
  const Result stiff = kinema_cli("run " + drag.string() + " -q");
  CHECK(stiff.err.find("past the largest stable step of implicit_euler") != std::string::npos);
  CHECK(stiff.err.find("--method implicit_euler or ros2") == std::string::npos);
  const Result rigid = kinema_cli("run " + scene("box_chain.json") + " -q --steps 2 --method ros2");
  CHECK(rigid.code != 0);
  CHECK(rigid.err.find("ros2 (implicit) steps particles without events: this scene has rigid bodies") != std::string::npos);
}
