// Checkpoints through the program: a run stopped (by a signal, or killed outright) and resumed
// in a new process ends with the bits of a run never stopped; every file it writes is whole;
// summaries say what went wrong; hostile checkpoints are refused with one line.
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <random>
#include <sys/stat.h>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli_support.hpp"
#include "kinema/checkpoint.hpp"

namespace fs = std::filesystem;
using kinema::test::read;
using kinema::test::Result;
using kinema::test::run_kinema;
using kinema::test::work_dir;
using kinema::test::write;
using Json = nlohmann::json;

namespace {

std::string scene(const std::string& name) { return std::string(KINEMA_SCENES) + "/" + name; }

// A sanitized build (unoptimized) steps far slower: its runs take an eightieth of the steps, so
// that signals and kills still land mid-run without the suite taking minutes, and it kills
// fewer times (it looks for memory errors; the release run counts the kills).
#ifdef KINEMA_SANITIZED
constexpr long kSlower = 80;
constexpr int kKills = 2;
constexpr int kKillAfterMs[2] = {1500, 3000};  // its start (the stiffness estimate) takes a second
const char* const kStressBodies = "4000";       // N-body among N/16 of them
#else
constexpr long kSlower = 1;
constexpr int kKills = 30;
constexpr int kKillAfterMs[2] = {100, 600};
const char* const kStressBodies = "20000";
#endif
std::string steps(long n) { return std::to_string(n / kSlower); }

std::vector<std::string> with(std::vector<std::string> args, const std::vector<std::string>& more) {
  args.insert(args.end(), more.begin(), more.end());
  return args;
}

// Waits (a minute at most) until `path` exists, then sends `signal`.
// Waits (a minute at most) for `path` to exist.
void wait_for(const fs::path& path) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::minutes(1);
  while (!fs::exists(path) && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

std::function<void(pid_t)> signal_once_written(const fs::path& path, int signal) {
  return [=](pid_t pid) {
    wait_for(path);
    ::kill(pid, signal);
  };
}

Json summary_of(const fs::path& path) { return Json::parse(read(path)); }

// No temporary left beside the outputs.
bool only_outputs_in(const fs::path& dir) {
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().filename().string().find(".tmp-") != std::string::npos) return false;
  }
  return true;
}

// `args` straight, and the same stopped by SIGINT at its first checkpoint then resumed with one
// thread: the same final state (state_crc32c) and the same trajectory, if any.
void check_resumes(const std::vector<std::string>& args, const std::string& csv_name = "") {
  const fs::path dir = work_dir(), ckpt = dir / "run.ckpt";
  fs::remove(ckpt);
  const std::vector<std::string> out_straight = csv_name.empty() ? std::vector<std::string>{}
                                                                 : std::vector<std::string>{"--out", (dir / ("a_" + csv_name)).string()};
  const std::vector<std::string> out_resumed = csv_name.empty() ? std::vector<std::string>{}
                                                                : std::vector<std::string>{"--out", (dir / ("b_" + csv_name)).string()};
  const Result straight = run_kinema(with(with(args, out_straight), {"--summary", (dir / "straight.json").string()}));
  REQUIRE(straight.code == 0);
  const Json a = summary_of(dir / "straight.json");
  REQUIRE(a["complete"] == true);

  const Result stopped = run_kinema(
      with(with(args, out_resumed), {"--summary", (dir / "stopped.json").string(), "--checkpoint", ckpt.string(),
                                     "--checkpoint-every", "0.05"}),
      {}, signal_once_written(ckpt, SIGINT));
  CHECK(stopped.code == 128 + SIGINT);
  const Json b = summary_of(dir / "stopped.json");
  CHECK(b["complete"] == false);
  CHECK(b["interrupted"] == "SIGINT");
  CHECK(b["error"] == "stopped by SIGINT");
  CHECK(b["checkpoints_written"].get<int>() >= 2);  // the first, and the one at the signal

  const Result resumed = run_kinema(
      with(with(args, out_resumed), {"--summary", (dir / "resumed.json").string(), "--resume", ckpt.string(),
                                     "--threads", "1"}));
  REQUIRE(resumed.code == 0);
  const Json c = summary_of(dir / "resumed.json");
  CHECK(c["complete"] == true);
  CHECK(c["resumed_from"]["checkpoint"] == ckpt.string());
  CHECK(c["state_crc32c"] == a["state_crc32c"]);
  CHECK(c["steps"] == a["steps"]);
  CHECK(c["force_evaluations"] == a["force_evaluations"]);
  if (!csv_name.empty()) CHECK(read(dir / ("a_" + csv_name)) == read(dir / ("b_" + csv_name)));
  CHECK(only_outputs_in(dir));
}

}  // namespace

TEST_CASE("run --resume: particles under local terms, the trajectory continued without a gap or a repeat",
          "[cli][checkpoint]") {
  check_resumes({"run", scene("projectiles.json"), "-q", "--steps", steps(3000000), "--every", steps(100000)}, "projectiles.csv");
}

TEST_CASE("run --resume: springs (the staged path) in float", "[cli][checkpoint]") {
  check_resumes({"run", scene("cloth.json"), "-q", "--steps", steps(40000), "--every", steps(4000)}, "cloth.csv");
}

TEST_CASE("run --resume: error control stopped inside a call goes on bit for bit", "[cli][checkpoint][adaptive]") {
  check_resumes({"run", scene("cloth.json"), "-q", "--method", "dopri5", "--rtol", "1e-6", "--steps", steps(6000)});
}

TEST_CASE("run --resume: 100k rigid bodies", "[cli][checkpoint][rigid]") {
  check_resumes({"run", scene("spinning_debris.json"), "-q", "--steps", steps(3000)});
}

TEST_CASE("run --checkpoint survives SIGKILL at 30 random moments", "[cli][checkpoint][crash]") {
  // Every 0.2 s a checkpoint; each kill leaves one that loads, and the run resumed over and
  // over ends with the final state and trajectory of a run never killed.
  const fs::path dir = work_dir(), ckpt = dir / "crash.ckpt", csv = dir / "crash.csv";
  const std::vector<std::string> args{"run", scene("cloth.json"), "-q", "--steps", steps(240000), "--every", steps(20000)};
  REQUIRE(run_kinema(with(args, {"--summary", (dir / "whole.json").string(), "--out", (dir / "whole.csv").string()}))
              .code == 0);
  std::mt19937 random(20261202);
  std::uniform_int_distribution<int> delay_ms(kKillAfterMs[0], kKillAfterMs[1]);
  int kills = 0;
  for (int attempt = 0; attempt < kKills; ++attempt) {
    std::vector<std::string> run = with(args, {"--out", csv.string(), "--checkpoint", ckpt.string(),
                                               "--checkpoint-every", "0.2"});
    if (fs::exists(ckpt)) run = with(run, {"--resume", ckpt.string()});
    const Result r = run_kinema(run, {}, [&](pid_t pid) {
      // The first kill comes once a checkpoint exists: a loaded machine (a sanitized run) can
      // take longer than any fixed delay to start stepping.
      wait_for(ckpt);
      std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms(random)));
      ::kill(pid, SIGKILL);
    });
    kills += r.killed;
    if (fs::exists(ckpt)) CHECK(kinema::CheckpointReader::load(ckpt).records() == 2);
  }
  CHECK(kills == kKills);  // every one landed in a run still going
  REQUIRE(fs::exists(ckpt));
  const Result last = run_kinema(with(args, {"--out", csv.string(), "--resume", ckpt.string(), "--summary",
                                             (dir / "last.json").string()}));
  REQUIRE(last.code == 0);
  CHECK(summary_of(dir / "last.json")["state_crc32c"] == summary_of(dir / "whole.json")["state_crc32c"]);
  CHECK(summary_of(dir / "last.json")["resumed_from"]["step"].get<long>() > 0);
  CHECK(read(csv) == read(dir / "whole.csv"));
}

TEST_CASE("stress --resume: the built-in scene's groups, drifts and report go on", "[cli][checkpoint][stress]") {
  const fs::path dir = work_dir(), ckpt = dir / "stress.ckpt";
  const std::vector<std::string> args{"stress", "-q", "--bodies", kStressBodies, "--steps", "150"};
  REQUIRE(run_kinema(with(args, {"--report", (dir / "whole.json").string()})).code == 0);
  const Result stopped = run_kinema(with(args, {"--report", (dir / "stopped.json").string(), "--checkpoint",
                                                ckpt.string(), "--checkpoint-every", "0.05"}),
                                    {}, signal_once_written(ckpt, SIGTERM));
  CHECK(stopped.code == 128 + SIGTERM);
  const Result resumed = run_kinema(with(args, {"--report", (dir / "resumed.json").string(), "--resume", ckpt.string()}));
  REQUIRE(resumed.code == 0);
  const Json whole = summary_of(dir / "whole.json"), again = summary_of(dir / "resumed.json");
  CHECK(again["state_crc32c"] == whole["state_crc32c"]);
  CHECK(again["steps"] == whole["steps"]);
  CHECK(again["complete"] == true);
  CHECK(again["resumed_from"]["step"].get<long>() > 0);
  for (std::size_t g = 0; g < whole["groups"].size(); ++g) {
    for (const char* drift : {"energy_drift", "momentum_drift"}) {
      // The worst drift is sampled when wall-clock intervals close; the final one is the state's.
      if (whole["groups"][g].contains(drift)) CHECK(again["groups"][g][drift]["final"] == whole["groups"][g][drift]["final"]);
    }
  }
}

TEST_CASE("state_crc32c tells runs apart by their clocks where the bodies end alike", "[cli][checkpoint]") {
  // A body at rest on an anchor at its own position: only the clock moves.
  const fs::path scene = write("still.json", R"({"precision": "double", "particles": [{"position": [0, 0, 0]}],
      "forces": [{"type": "spring", "k": 1}]})");
  const auto crc_after = [&](const std::string& steps, const std::string& dt) {
    const fs::path summary = work_dir() / "still_summary.json";
    REQUIRE(run_kinema({"run", scene.string(), "-q", "--steps", steps, "--dt", dt, "--summary", summary.string()}).code == 0);
    return summary_of(summary)["state_crc32c"].get<std::string>();
  };
  const std::string ten = crc_after("10", "0.01");
  CHECK(crc_after("10", "0.01") == ten);
  CHECK(crc_after("20", "0.01") != ten);
  CHECK(crc_after("10", "0.02") != ten);
  CHECK(crc_after("0", "0.01") != ten);
}

TEST_CASE("a summary on every exit: --strict, error control giving up, a failed write", "[cli][checkpoint]") {
  const fs::path dir = work_dir(), summary = dir / "s.json";
  const auto failed = [&](const std::vector<std::string>& args, const std::string& error) {
    fs::remove(summary);
    const Result r = run_kinema(with(args, {"--summary", summary.string()}));
    CHECK(r.code == 1);
    const Json j = summary_of(summary);
    CHECK(j["complete"] == false);
    CHECK_THAT(j["error"].get<std::string>(), Catch::Contains(error));
    return j;
  };
  failed({"run", scene("cloth.json"), "-q", "--dt", "0.01", "--strict"}, "(--strict)");
  failed({"run", scene("cloth.json"), "-q", "--out", "/dev/full"}, "cannot write the trajectory");
  // One body falls straight into the attractor: error control cannot follow it, and says which.
  const fs::path plunge = write("plunge.json", R"({"precision": "double", "method": "dopri5", "rtol": 1e-9,
      "dt": 0.1, "steps": 20, "forces": [{"type": "central", "center": [0, 0, 0], "mu": 1}],
      "particles": [{"position": [3, 0, 0], "velocity": [0, 0.5, 0]}, {"position": [1, 0, 0]},
                    {"position": [0, 2, 0], "velocity": [0.7, 0, 0]}]})");
  const Json j = failed({"run", plunge.string(), "-q"}, "step size underflows");
  CHECK_THAT(j["error"].get<std::string>(), Catch::Contains("body 1's vx has the largest error"));
  CHECK(j["t_final"].get<double>() > 1.1);  // how far it got: the fall takes pi / 2^1.5 = 1.1107
}

TEST_CASE("an earlier summary is replaced only by a whole one", "[cli][checkpoint]") {
  const fs::path dir = work_dir(), summary = write("kept.json", "{\"earlier\": true}\n");
  const Result killed = run_kinema({"run", scene("cloth.json"), "-q", "--steps", steps(100000), "--summary", summary.string()},
                                   {}, [](pid_t pid) {
                                     std::this_thread::sleep_for(std::chrono::milliseconds(500));
                                     ::kill(pid, SIGKILL);
                                   });
  CHECK(killed.killed);
  CHECK(read(summary) == "{\"earlier\": true}\n");
  CHECK(only_outputs_in(dir));
  REQUIRE(run_kinema({"run", scene("cloth.json"), "-q", "--steps", "10", "--summary", summary.string()}).code == 0);
  CHECK(summary_of(summary)["complete"] == true);
}

TEST_CASE("run --resume refuses what is not this run's checkpoint, in one line", "[cli][checkpoint][hostile]") {
  const fs::path dir = work_dir(), ckpt = dir / "good.ckpt";
  const std::vector<std::string> cloth{"run", scene("cloth.json"), "-q", "--steps", "20"};
  REQUIRE(run_kinema(with(cloth, {"--checkpoint", ckpt.string()})).code == 0);
  const std::string bytes = read(ckpt);
  const fs::path stress_ckpt = dir / "stress.ckpt";
  REQUIRE(run_kinema({"stress", "-q", "--bodies", "100", "--steps", "2", "--checkpoint", stress_ckpt.string()}).code == 0);
  const std::vector<std::pair<fs::path, std::string>> cases{
      {dir, "is a directory"},
      {write("empty.ckpt", ""), "the file is empty"},
      {write("cut.ckpt", bytes.substr(0, bytes.size() / 2)), "truncated"},
      {write("text.ckpt", "{\"dt\": 0.01}"), "not a kinema checkpoint"},
      {stress_ckpt, "a checkpoint of kinema stress, not of kinema run"},
  };
  for (const auto& [path, why] : cases) {
    INFO(path);
    const Result r = run_kinema(with(cloth, {"--resume", path.string()}));
    CHECK(r.code == 1);
    CHECK_THAT(r.err, Catch::Contains(why));
    CHECK(kinema::test::lines(r.err) == 1);
  }
  // The same scene under another dt, and another scene: their results would not be this run's.
  for (const auto& other : {with(cloth, {"--dt", "0.0004"}),
                            std::vector<std::string>{"run", scene("hanging_chain.json"), "-q", "--steps", "20"}}) {
    const Result r = run_kinema(with(other, {"--resume", ckpt.string()}));
    CHECK(r.code == 1);
    CHECK_THAT(r.err, Catch::Contains("taken under another scene or other options"));
  }
}

TEST_CASE("run --resume of implicit steps takes the preconditioner they took, named or not", "[cli][checkpoint][implicit]") {
  // The 4096-body cloth: multigrid by default, so naming it resumes the run and Jacobi does not.
  const fs::path dir = work_dir(), ckpt = dir / "implicit.ckpt";
  const std::vector<std::string> cloth{"run", scene("cloth.json"), "-q", "--method", "implicit_euler",
                                       "--dt", "0.016666666666666666", "--steps", "3"};
  REQUIRE(run_kinema(with(cloth, {"--checkpoint", ckpt.string()})).code == 0);
  CHECK(run_kinema(with(cloth, {"--resume", ckpt.string(), "--implicit-preconditioner", "multigrid"})).code == 0);
  const Result jacobi = run_kinema(with(cloth, {"--resume", ckpt.string(), "--implicit-preconditioner", "jacobi"}));
  CHECK(jacobi.code == 1);
  CHECK_THAT(jacobi.err, Catch::Contains("taken under another scene or other options"));
}

TEST_CASE("outputs never overwrite the scene or each other", "[cli][checkpoint][hostile]") {
  const fs::path dir = work_dir();
  const fs::path scene_copy = write("mine.json", read(scene("projectiles.json")));
  const std::string before = read(scene_copy);
  const std::string same = (dir / "same.out").string(), other_name = (dir / "." / "same.out").string();
  const std::vector<std::vector<std::string>> cases{
      {"run", scene_copy.string(), "-q", "--summary", scene_copy.string()},
      {"run", scene_copy.string(), "-q", "--out", same, "--summary", other_name},
      {"run", scene_copy.string(), "-q", "--checkpoint", same, "--out", same},
      {"stress", "-q", "--scene", scene_copy.string(), "--report", scene_copy.string()},
      {"stress", "-q", "--bodies", "100", "--report", same, "--checkpoint", other_name},
      // Relative and absolute spellings of a file that does not exist yet (the program runs
      // in this process's folder).
      {"run", scene_copy.string(), "-q", "--out", "kinema-rel.out", "--summary", "./kinema-rel.out"},
      {"run", scene_copy.string(), "-q", "--out", "kinema-rel.out", "--checkpoint",
       (fs::current_path() / "kinema-rel.out").string()},
      {"stress", "-q", "--bodies", "100", "--report", "./kinema-rel.out", "--checkpoint", "kinema-rel.out"},
  };
  fs::remove("kinema-rel.out");
  for (const auto& args : cases) {
    INFO(args.back());
    const Result r = run_kinema(args);
    CHECK(r.code == 1);
    CHECK_THAT(r.err, Catch::Contains("one would overwrite the other"));
  }
  CHECK(read(scene_copy) == before);
  CHECK_FALSE(fs::exists(same));
  CHECK_FALSE(fs::exists("kinema-rel.out"));
  // Devices are no files to clobber.
  CHECK(run_kinema({"run", scene_copy.string(), "-q", "--out", "/dev/null", "--summary", "/dev/null"}).code == 0);
  // A --resume file is an input too, except to the --checkpoint that goes on from it.
  const std::string ck = (dir / "resume.ck").string(), stress_ck = (dir / "resume-stress.ck").string();
  REQUIRE(run_kinema({"run", scene_copy.string(), "-q", "--steps", "3", "--checkpoint", ck}).code == 0);
  REQUIRE(run_kinema({"stress", "-q", "--bodies", "100", "--steps", "3", "--checkpoint", stress_ck}).code == 0);
  const std::string saved = read(ck), stress_saved = read(stress_ck);
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"run", scene_copy.string(), "-q", "--steps", "3", "--resume", ck, "--summary", ck},
           {"run", scene_copy.string(), "-q", "--steps", "3", "--resume", ck, "--out", (dir / "." / "resume.ck").string()},
           {"stress", "-q", "--bodies", "100", "--steps", "3", "--resume", stress_ck, "--report", stress_ck}}) {
    INFO(args[args.size() - 2] << " " << args.back());
    const Result r = run_kinema(args);
    CHECK(r.code == 1);
    CHECK_THAT(r.err, Catch::Contains("is the input --resume names: one would overwrite the other"));
  }
  CHECK(read(ck) == saved);
  CHECK(read(stress_ck) == stress_saved);
  CHECK(run_kinema({"run", scene_copy.string(), "-q", "--steps", "3", "--resume", ck, "--checkpoint", ck}).code == 0);
}

TEST_CASE("an energy that overflows is said, not left as a silent null", "[cli][hostile]") {
  // G = 1e308 between two bodies half a unit apart: the state stays finite, the potential not.
  const fs::path scene_file = write("overflow.json", R"({"precision": "double", "dt": 0.001, "steps": 10,
      "forces": [{"type": "nbody", "G": 1e308}], "particles": [{"position": [0, 0, 0]}, {"position": [0.5, 0, 0]}]})");
  const fs::path summary = work_dir() / "overflow_summary.json";
  const Result r = run_kinema({"run", scene_file.string(), "-q", "--summary", summary.string()});
  CHECK(r.code == 0);
  CHECK_THAT(r.err, Catch::Contains("warning: the total energy at the start and the end overflows double"));
  CHECK_THAT(r.err, Catch::Contains("energy_initial and energy_final are null in the summary"));
  CHECK(summary_of(summary)["energy_initial"].is_null());
  CHECK(summary_of(summary)["energy_final"].is_null());
}

TEST_CASE("a full device for the summary or report is refused before any step", "[cli][hostile]") {
  // A run of 10^9 steps: refused at once, or this test would not end.
  const Result run = run_kinema({"run", scene("projectiles.json"), "-q", "--steps", "1000000000", "--summary", "/dev/full"});
  CHECK(run.code == 1);
  CHECK_THAT(run.err, Catch::Contains("/dev/full: cannot write the summary: No space left on device"));
  const Result stress = run_kinema({"stress", "-q", "--bodies", "100", "--seconds", "3600", "--report", "/dev/full"});
  CHECK(stress.code == 1);
  CHECK_THAT(stress.err, Catch::Contains("cannot write the report"));
  // A device that takes it gets valid JSON after the newline.
  const fs::path out = work_dir() / "stdout_summary.txt";
  REQUIRE(run_kinema({"run", scene("projectiles.json"), "-q", "--steps", "10", "--summary", "/dev/stdout"}, out).code == 0);
  CHECK(Json::parse(read(out))["steps"] == 10);
}

TEST_CASE("a FIFO with no other end, as scene or summary, is answered at once", "[cli][hostile]") {
  const fs::path fifo = work_dir() / "nobody.fifo";
  fs::remove(fifo);
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  // A watchdog: a run still blocked after 20 s is killed (the checks below then fail); it
  // stands down as soon as the run has ended, before its pid can be another's.
  const auto watched = [](const std::vector<std::string>& args) {
    std::atomic<bool> ended{false};
    std::thread watchdog;
    const Result r = run_kinema(args, {}, [&](pid_t pid) {
      watchdog = std::thread([&ended, pid] {
        for (int i = 0; i < 200 && !ended; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
        if (!ended) ::kill(pid, SIGKILL);
      });
    });
    ended = true;
    watchdog.join();
    return r;
  };
  const Result as_scene = watched({"run", fifo.string(), "-q"});
  CHECK_FALSE(as_scene.killed);
  CHECK(as_scene.code == 1);
  const Result as_summary = watched({"run", scene("projectiles.json"), "-q", "--summary", fifo.string()});
  CHECK_FALSE(as_summary.killed);
  CHECK(as_summary.code == 1);
  CHECK_THAT(as_summary.err, Catch::Contains("cannot write the summary"));
  fs::remove(fifo);
}
