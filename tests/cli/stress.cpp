// kinema stress: the built-in scene, the finiteness guard's three policies through the
// command line, signals and bad options.
#include <catch2/catch.hpp>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli_support.hpp"
#include "kinema/isa.hpp"

namespace fs = std::filesystem;
using kinema::test::read;
using kinema::test::Result;
using kinema::test::run_kinema;
using kinema::test::work_dir;
using kinema::test::write;
using Json = nlohmann::json;

namespace {

Json report_of(const std::vector<std::string>& args, Result& r) {
  const fs::path report = work_dir() / "stress.json";
  fs::remove(report);
  std::vector<std::string> all{"stress", "-q", "--report", report.string()};
  all.insert(all.end(), args.begin(), args.end());
  r = run_kinema(all);
  return fs::exists(report) ? Json::parse(read(report)) : Json{};
}

const Json* group(const Json& report, const std::string& name) {
  for (const Json& g : report["groups"]) {
    if (g["name"] == name) return &g;
  }
  return nullptr;
}

// A light body on a stiff anchor spring under explicit Euler: w h = 10, so its amplitude
// grows tenfold per step; the heavy one (w h = 1e-3) stays put.
fs::path blow_up_scene() {
  return write("stress_blowup.json", R"({"method": "euler", "dt": 0.1, "steps": 1000,
      "particles": [{"position": [0.5, 0, 0], "mass": 1e8}, {"position": [1, 0, 0], "mass": 1}],
      "forces": [{"type": "spring", "anchor": [0, 0, 0], "k": 1e4}]})");
}

}  // namespace

TEST_CASE("stress: the built-in scene stays finite, its isolated groups keep their momentum", "[cli][stress]") {
  Result r;
  const Json j = report_of({"--bodies", "3000", "--steps", "100"}, r);
  REQUIRE(r.code == 0);
  CHECK(r.out.empty());
  CHECK(j["finite"] == true);
  CHECK(j["steps"] == 100);
  CHECK(j["bodies"] == 3000);
  std::size_t bodies = 0;
  for (const Json& g : j["groups"]) bodies += g["bodies"].get<std::size_t>();
  CHECK(bodies == 3000);
  for (const char* name : {"field", "network", "cluster", "spinning", "free_rigid"}) {
    INFO(name);
    REQUIRE(group(j, name) != nullptr);
  }
  // Springs act on both ends with the same bits and gravity is a sum over all: no outside
  // force, so momentum moves by round-off only.
  CHECK((*group(j, "network"))["momentum_drift"]["worst"].get<double>() < 1e-6);
  CHECK((*group(j, "cluster"))["momentum_drift"]["worst"].get<double>() < 1e-6);
  CHECK((*group(j, "free_rigid"))["energy_drift"]["worst"].get<double>() < 1e-4);
  CHECK_FALSE(group(j, "field")->contains("energy_drift"));  // drag: nothing to conserve
  CHECK(j["throughput"]["intervals"].get<int>() >= 1);
  CHECK(j["memory"]["state_bytes"].get<double>() > 3000 * 7 * 4);
  CHECK(j["memory"]["peak_resident_bytes"].get<double>() > 0);
}

TEST_CASE("stress: a seed makes the same scene and the same bits on any thread count or instruction set",
          "[cli][stress]") {
  const auto drifts = [](const std::vector<std::string>& extra) {
    std::vector<std::string> args{"--bodies", "5000", "--steps", "40"};
    args.insert(args.end(), extra.begin(), extra.end());
    Result r;
    const Json j = report_of(args, r);
    REQUIRE(r.code == 0);
    // The final state's drifts ("worst" is sampled at wall-clock intervals).
    return std::vector<Json>{(*group(j, "network"))["energy_drift"]["final"],
                             (*group(j, "cluster"))["momentum_drift"]["final"],
                             (*group(j, "free_rigid"))["energy_drift"]["final"]};
  };
  const auto reference = drifts({"--threads", "1"});
  CHECK(drifts({"--threads", "2"}) == reference);
  const char* narrow = kinema::isa_available(kinema::Isa::sse2) ? "sse2" : "scalar";  // a sanitized build may have no sse2
  CHECK(drifts({"--threads", "2", "--isa", narrow}) == reference);
  CHECK(drifts({"--seed", "2"}) != reference);
}

TEST_CASE("stress: the guard's three policies on a scene that blows up", "[cli][stress][guard]") {
  const fs::path scene = blow_up_scene();
  // kinema run replays the run step by step to find where it stopped being finite.
  const fs::path summary = work_dir() / "blowup_summary.json";
  const Result run = run_kinema({"run", scene.string(), "-q", "--summary", summary.string()});
  REQUIRE(run.code == 3);
  const Json expected = Json::parse(read(summary))["first_non_finite"];
  REQUIRE(expected.contains("step"));

  Result r;
  Json j = report_of({"--scene", scene.string(), "--guard", "check"}, r);
  CHECK(r.code == 3);
  CHECK(r.err.find("group particles is no longer finite at step " + expected["step"].dump()) != std::string::npos);
  const Json& at = j["first_non_finite"];
  CHECK(at["step"] == expected["step"]);
  CHECK(at["body"] == 1);
  CHECK(at["field"] == expected["field"]);
  CHECK(at["state_kept_at_step"] == expected["step"].get<int>() - 1);
  CHECK(j["complete"] == false);
  CHECK(j["error"] == "group particles is no longer finite at step " + expected["step"].dump() + ": body 1, " +
                         expected["field"].get<std::string>());  // what ended it, as on stderr
  // One group: the steps it completed, those of the state kept (and of its CRC), in the
  // report and in its intervals alike.
  CHECK(j["steps"].get<int>() == expected["step"].get<int>() - 1);
  int interval_steps = 0;
  for (const Json& i : j["intervals"]) interval_steps += i["steps"].get<int>();
  CHECK(interval_steps <= j["steps"].get<int>());  // a last interval under half a one is not closed

  j = report_of({"--scene", scene.string(), "--guard", "clamp", "--max-speed", "100"}, r);
  CHECK(r.code == 0);
  CHECK(j["finite"] == true);
  CHECK(j["steps"] == 1000);

  j = report_of({"--scene", scene.string(), "--guard", "off"}, r);
  CHECK(r.code == 3);
  const Json& off = j["first_non_finite"];
  const int step = expected["step"];
  if (off.contains("step")) {
    CHECK(off["step"] == step);
  } else {
    CHECK(off["between_steps"][0].get<int>() <= step);
    CHECK(off["between_steps"][1].get<int>() >= step);
    CHECK(j["steps"] == off["between_steps"][1]);  // unguarded, the state is the chunk's end
  }
}

TEST_CASE("stress: SIGINT stops the run between steps and the report is written", "[cli][stress][signals]") {
  const fs::path report = work_dir() / "interrupted_stress.json";
  fs::remove(report);
  // Long enough for the first steps even in a sanitized build on a loaded machine.
  const Result r = run_kinema({"stress", "-q", "--bodies", "20000", "--seconds", "300", "--report", report.string()},
                              {}, [](pid_t pid) {
                                std::this_thread::sleep_for(std::chrono::milliseconds(4000));
                                ::kill(pid, SIGINT);
                              });
  CHECK_FALSE(r.killed);
  CHECK(r.code == 128 + SIGINT);
  CHECK(r.err.find("stopped by SIGINT after step") != std::string::npos);
  CHECK(r.err.find("; the report is complete to there") != std::string::npos);
  REQUIRE(fs::exists(report));
  const Json j = Json::parse(read(report));
  CHECK(j["interrupted"] == "SIGINT");
  CHECK(j["finite"] == true);
  CHECK(j["steps"].get<long>() > 0);
  CHECK(j["wall_seconds"].get<double>() < 60);
}

TEST_CASE("stress: SIGINT without --report speaks of no report", "[cli][stress][signals]") {
  const Result r = run_kinema({"stress", "-q", "--bodies", "20000", "--seconds", "300"}, {}, [](pid_t pid) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));
    ::kill(pid, SIGINT);
  });
  CHECK_FALSE(r.killed);
  CHECK(r.code == 128 + SIGINT);
  CHECK(r.err.find("stopped by SIGINT after step") != std::string::npos);
  CHECK(r.err.find("report") == std::string::npos);
}

TEST_CASE("stress: bad options are refused before any work", "[cli][stress][errors]") {
  const fs::path scene = blow_up_scene();
  const std::vector<std::pair<std::vector<std::string>, int>> cases{
      {{"--steps", "10", "--seconds", "1"}, 2},
      {{"--scene", scene.string(), "--bodies", "10"}, 2},
      {{"--scene", scene.string(), "--seed", "3"}, 2},
      {{"--guard", "sometimes"}, 2},
      {{"--bodies", "0"}, 2},
      {{"--max-speed", "inf"}, 2},
      {{"--max-speed", "10"}, 2},  // without --guard clamp it would hold nothing
      {{"--max-angular-speed", "10", "--guard", "check"}, 2},
      {{"--method", "auto"}, 1},
      {{"--method", "rk5"}, 1},
      {{"--bodies", "1000000000"}, 1},  // more memory than the machine has
  };
  for (const auto& [args, code] : cases) {
    std::vector<std::string> all{"stress", "-q", "--steps", "1"};
    if (args.front() == "--steps") all = {"stress", "-q"};
    all.insert(all.end(), args.begin(), args.end());
    INFO(all.back());
    const Result r = run_kinema(all);
    CHECK(r.code == code);
    CHECK(r.err.find("error") != std::string::npos);
  }
  const Result full = run_kinema({"stress", "-q", "--bodies", "100", "--steps", "1", "--report", "/dev/full"});
  CHECK(full.code == 1);
  CHECK(full.err.find("cannot write the report") != std::string::npos);
}

TEST_CASE("stress: every method runs the built-in scene and a rigid scene, the report whole", "[cli][stress]") {
  const fs::path rigid = write("stress_rigid.json", R"({"steps": 5, "dt": 0.01,
      "rigid_bodies": [{"position": [0,0,0], "angular_velocity": [1,2,3], "inertia": [1,2,3]},
                       {"position": [1,0,0], "velocity": [0,1,0]}],
      "forces": [{"type": "gravity", "g": [0,-9.81,0]}, {"type": "angular_drag", "c": 0.1}]})");
  for (const std::string method : {"euler", "rk4", "velocity_verlet", "bs3", "dopri5", "rk6"}) {
    for (const bool file : {false, true}) {
      INFO(method << (file ? " on the rigid scene" : " on the built-in scene"));
      const fs::path report = work_dir() / "stress_method.json";
      std::vector<std::string> args{"stress", "-q", "--steps", "5", "--method", method, "--report", report.string()};
      if (file) args.insert(args.end(), {"--scene", rigid.string()});
      else args.insert(args.end(), {"--bodies", "2000"});
      const Result r = run_kinema(args);
      CHECK(r.code == 0);
      CHECK(r.err.empty());
      const auto j = nlohmann::json::parse(read(report));
      CHECK(j["method"] == method);
      CHECK(j["complete"] == true);
      CHECK(j["steps"] == 5);
    }
  }
}
