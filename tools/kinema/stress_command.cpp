#include "stress_command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <unistd.h>
#include <vector>

#include <nlohmann/json.hpp>

#include "interrupt.hpp"
#include "numbers.hpp"
#include "progress.hpp"
#include "report_file.hpp"
#include "stress_scene.hpp"

namespace kinema::cli {
namespace {

using Clock = std::chrono::steady_clock;
using Json = nlohmann::ordered_json;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Resident and peak resident memory of this process, from /proc/self/status (0 elsewhere).
struct Memory {
  double resident = 0, peak = 0;
};

Memory memory_now() {
  Memory m;
  std::ifstream status("/proc/self/status");
  std::string key;
  double kib = 0;
  while (status >> key) {
    if (key == "VmRSS:" && status >> kib) m.resident = kib * 1024;
    else if (key == "VmHWM:" && status >> kib) m.peak = kib * 1024;
  }
  return m;
}

// A chunk of steps takes about this long: short enough to answer a signal and to cut
// intervals finely, long enough that the per-call copy and scan of the guard cost little.
constexpr double kChunkSeconds = 0.05;

// A rough upper bound on what the built-in scene takes per body (state, stage scratch,
// spring slots, the guard's copy), to refuse a size that cannot fit before building it.
constexpr double kBytesPerBodyPerScalar = 96;

struct Interval {
  double end_seconds;  // since the stepping started
  std::uint64_t steps;
  double body_steps_per_second;
  double resident;
};

// Where a group's state stopped being finite: exactly at `last` when first == last.
struct Failure {
  std::string group;
  std::size_t body;
  std::string field;
  std::uint64_t first, last;
};

// A conserved quantity's worst relative drift from its start, over the intervals.
struct Drift {
  double start = 0, scale = 1, worst = 0, last = 0;
  void see(double value) {
    last = (value - start) / scale;
    worst = std::max(worst, std::abs(last));
  }
};

template <class T>
struct Conservation {
  Drift energy, momentum;
  Vec3<double> momentum_start{};
};

double length(const Vec3<double>& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

template <class T>
Conservation<T> conservation_start(const StressGroup<T>& g) {
  Conservation<T> c;
  if (g.conserves_energy()) {
    c.energy.start = g.energy();
    c.energy.scale = std::max(std::abs(c.energy.start), std::numeric_limits<double>::min());
  }
  if (g.conserves_momentum()) {
    c.momentum_start = g.momentum();
    c.momentum.scale = std::max(g.momentum_scale(), std::numeric_limits<double>::min());
  }
  return c;
}

template <class T>
void conservation_update(const StressGroup<T>& g, Conservation<T>& c) {
  if (g.conserves_energy()) c.energy.see(g.energy());
  if (g.conserves_momentum()) {
    const Vec3<double> p = g.momentum();
    c.momentum.see(length({p[0] - c.momentum_start[0], p[1] - c.momentum_start[1], p[2] - c.momentum_start[2]}));
  }
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : (v[n / 2 - 1] + v[n / 2]) / 2;
}

// Throughput over the intervals: spread and trend (last quarter against the first).
Json throughput_report(const std::vector<Interval>& intervals) {
  std::vector<double> rates;
  for (const Interval& i : intervals) rates.push_back(i.body_steps_per_second);
  Json j;
  j["intervals"] = rates.size();
  if (rates.empty()) return j;
  j["min"] = *std::min_element(rates.begin(), rates.end());
  j["median"] = median(rates);
  j["max"] = *std::max_element(rates.begin(), rates.end());
  if (rates.size() >= 8) {
    const std::size_t q = rates.size() / 4;
    const double first = median({rates.begin(), rates.begin() + std::ptrdiff_t(q)});
    const double last = median({rates.end() - std::ptrdiff_t(q), rates.end()});
    j["last_quarter_over_first"] = last / first;
  }
  return j;
}

std::string guard_name(FiniteGuard g) {
  return g == FiniteGuard::off ? "off" : g == FiniteGuard::check ? "check" : "clamp";
}

double mib(double bytes) { return bytes / double(1 << 20); }
double mib(const Json& bytes) { return mib(bytes.get<double>()); }

// The groups to step and how far: from a scene file, or the built-in randomized scene.
template <class T>
struct StressSetup {
  std::vector<StressGroup<T>> groups;
  std::string name;
  double dt = 0;
  std::size_t bodies = 0;
  std::uint64_t steps = 0;  // the most: a wall-clock budget may end the run first
};

StepperOptions stress_stepper_options(const StressOptions& o) {
  StepperOptions options;
  options.isa = o.isa;
  options.threads = std::min(o.threads == 0 ? hardware_threads() : o.threads, hardware_threads());
  options.guard = o.guard;
  options.max_speed = o.max_speed, options.max_angular_speed = o.max_angular_speed;
  return options;
}

template <class T>
StressSetup<T> set_up(const StressOptions& o, const Scene* scene) {
  const StepperOptions options = stress_stepper_options(o);
  const Method& method = method_by_name(scene ? scene->method : o.method.value_or("rk4"));
  StressSetup<T> s;
  s.groups = scene ? scene_stress_groups<T>(*scene, method, options)
                   : random_stress_groups<T>(o.bodies, o.seed, method, options);
  if (s.groups.empty()) throw Error("the scene has no bodies");
  s.dt = o.dt ? *o.dt : scene ? scene->dt : kStressDt;
  for (const auto& g : s.groups) {
    g.stepper().check_step_size(T(s.dt));
    s.bodies += g.size();
  }
  s.name = scene ? scene->name : "random (seed " + std::to_string(o.seed) + ")";
  s.steps = o.seconds ? std::numeric_limits<std::uint64_t>::max()
                      : o.steps ? *o.steps : scene ? scene->steps : 1000;
  return s;
}

// What stepping did.
struct StressOutcome {
  std::uint64_t done = 0;  // steps completed by every group
  double stepping_seconds = 0;
  double elapsed_seconds = 0;  // since the stepping started, earlier runs of a resumed one included
  std::vector<Interval> intervals;
  std::optional<Failure> failure;
  std::optional<std::uint64_t> resumed_at;  // the step a checkpoint resumed the run from
  std::uint64_t checkpoints = 0;
};

// What the run's results depend on: the scene (file, or the built-in one's size and seed) and
// the options that change them (not --threads, --isa or --interval).
std::string stress_fingerprint(const StressOptions& o, const std::string& method, Precision p, double dt) {
  char text[400];
  std::snprintf(text, sizeof text, "bodies=%llu seed=%llu method=%s precision=%d dt=%a steps=%lld seconds=%a guard=%d "
                "max_speed=%a max_angular=%a", static_cast<unsigned long long>(o.scene_path.empty() ? o.bodies : 0),
                static_cast<unsigned long long>(o.scene_path.empty() ? o.seed : 0), method.c_str(), int(p), dt,
                o.steps ? static_cast<long long>(*o.steps) : -1LL, o.seconds.value_or(-1), int(o.guard), o.max_speed,
                o.max_angular_speed);
  return fingerprint_of(o.scene_path, text);
}

nlohmann::json drift_record(const Drift& d) {
  return {exact(d.start), exact(d.scale), exact(d.worst), exact(d.last)};
}
Drift drift_from(const nlohmann::json& j) {
  return {exact(j.at(0).get<std::uint64_t>()), exact(j.at(1).get<std::uint64_t>()), exact(j.at(2).get<std::uint64_t>()),
          exact(j.at(3).get<std::uint64_t>())};
}

template <class T>
RunRecord stress_record(const std::string& fingerprint, const StressOutcome& out,
                        const std::vector<Conservation<T>>& conservation) {
  nlohmann::json f = {{"done", out.done}, {"stepping_seconds", exact(out.stepping_seconds)},
                      {"elapsed_seconds", exact(out.elapsed_seconds)}};
  for (const Interval& i : out.intervals) {
    f["intervals"].push_back({exact(i.end_seconds), i.steps, exact(i.body_steps_per_second), exact(i.resident)});
  }
  for (const Conservation<T>& c : conservation) {
    nlohmann::json g = {{"energy", drift_record(c.energy)}, {"momentum", drift_record(c.momentum)}};
    for (double p : c.momentum_start) g["momentum_start"].push_back(exact(p));
    f["groups"].push_back(g);
  }
  return {"stress", fingerprint, f};
}

template <class T>
void resume_from(const nlohmann::json& f, StressOutcome& out, std::vector<Conservation<T>>& conservation) {
  out.done = f.at("done"), out.resumed_at = out.done;
  out.stepping_seconds = exact(f.at("stepping_seconds").get<std::uint64_t>());
  out.elapsed_seconds = exact(f.at("elapsed_seconds").get<std::uint64_t>());
  if (f.contains("intervals")) {
    for (const auto& i : f.at("intervals")) {
      out.intervals.push_back({exact(i.at(0).get<std::uint64_t>()), i.at(1).get<std::uint64_t>(),
                               exact(i.at(2).get<std::uint64_t>()), exact(i.at(3).get<std::uint64_t>())});
    }
  }
  const auto& groups = f.at("groups");
  if (groups.size() != conservation.size()) throw Error("its groups are not this run's");
  for (std::size_t k = 0; k < conservation.size(); ++k) {
    conservation[k].energy = drift_from(groups[k].at("energy"));
    conservation[k].momentum = drift_from(groups[k].at("momentum"));
    for (int d = 0; d < 3; ++d) conservation[k].momentum_start[d] = exact(groups[k].at("momentum_start").at(d).get<std::uint64_t>());
  }
}

// The groups as the checkpoint left them, and the run's progress and drifts then.
template <class T>
StressOutcome resume_stress(const std::string& path, const std::string& fingerprint, std::vector<StressGroup<T>>& groups,
                            std::vector<Conservation<T>>& conservation) {
  const CheckpointReader in = CheckpointReader::load(path);
  const RunRecord record = decode(in.user_data(), "stress", fingerprint, path);
  StressOutcome out;
  try {
    if (in.records() != groups.size()) throw Error("it holds " + std::to_string(in.records()) + " groups, this run " +
                                                   std::to_string(groups.size()));
    for (std::size_t k = 0; k < groups.size(); ++k) groups[k].restore(in, k);
    resume_from(record.fields, out, conservation);
  } catch (const nlohmann::json::exception&) {
    throw Error(printable(path) + ": its run record is incomplete");
  } catch (const Error& e) {
    throw Error(printable(path) + ": " + e.what());
  }
  return out;
}

// Steps every group in chunks of about kChunkSeconds until the steps, the wall-clock budget,
// a failure or a signal ends it, closing a throughput interval every o.interval seconds.
template <class T>
class StressLoop {
 public:
  // `resumed`: where a checkpoint left the run (a fresh one: nothing done).
  StressLoop(const StressOptions& o, StressSetup<T>& setup, std::vector<Conservation<T>>& conservation,
             StressOutcome resumed, std::string fingerprint)
      : o_(o), setup_(setup), conservation_(conservation), out_(std::move(resumed)),
        fingerprint_(std::move(fingerprint)), checkpoints_(o.checkpoint) {}

  StressOutcome run() {
    Progress progress("kinema stress", o_.quiet);
    // Time goes on from where a resumed run stopped: intervals and the --seconds budget count it.
    start_ = Clock::now() - std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(out_.elapsed_seconds));
    open_.start = out_.elapsed_seconds;
    std::uint64_t chunk = 1;
    while (!stopped()) {
      const std::uint64_t n = std::min(chunk, setup_.steps - out_.done);
      chunk = next_chunk(n, timed_advance(n));
      const double now = seconds_since(start_);
      if (interval_due(now)) close_interval(now);
      progress.update(o_.seconds ? std::min(1.0, now / *o_.seconds) : double(out_.done) / double(setup_.steps));
      if (checkpoints_.due() && !out_.failure) save_checkpoint(), checkpoints_.saved();
    }
    // The end, or where a signal stopped it; a failure keeps the last checkpoint before it.
    if (checkpoints_.enabled() && !out_.failure) save_checkpoint();
    progress.finish();
    return out_;
  }

 private:
  // The steps done or the wall-clock budget spent.
  bool finished() const {
    return out_.done >= setup_.steps || (o_.seconds && seconds_since(start_) >= *o_.seconds);
  }
  bool stopped() const { return finished() || out_.failure || interrupting_signal() != 0; }

  double timed_advance(std::uint64_t n) {
    const auto t0 = Clock::now();
    const std::uint64_t before = out_.done;
    advance(n);
    const double took = seconds_since(t0);
    out_.stepping_seconds += took, open_.stepping += took, open_.steps += out_.done - before;
    return took;
  }

  // A chunk that takes about kChunkSeconds, growing at most twofold at a time.
  static std::uint64_t next_chunk(std::uint64_t n, double took) {
    return std::clamp<std::uint64_t>(std::uint64_t(kChunkSeconds * double(n) / std::max(took, 1e-9)), 1, 2 * n);
  }

  // n steps of every group; under a guard a group that fails stops at its last finite step.
  // `done` counts the steps every group has taken: at a failure, the failing group's own
  // where it is the last (the groups before it took all n, those after none).
  void advance(std::uint64_t n) {
    for (auto& g : setup_.groups) {
      const bool last = &g == &setup_.groups.back();
      try {
        g.advance(T(setup_.dt), n);
      } catch (const NonFiniteError& e) {
        out_.failure = Failure{g.name(), e.body, e.field, out_.done + e.step, out_.done + e.step};
        if (last) out_.done += e.step - 1;
        return;
      }
      if (o_.guard == FiniteGuard::off) {
        if (const auto bad = g.first_non_finite()) {
          out_.failure = Failure{g.name(), bad->body, bad->field, out_.done + 1, out_.done + n};
          if (last) out_.done += n;
          return;
        }
      }
    }
    out_.done += n;
  }

  // Every o.interval seconds; at the end too, unless that interval would be shorter than half
  // of one (and one has closed already).
  bool interval_due(double now) const {
    const double open = now - open_.start;
    return open >= o_.interval || (stopped() && (out_.intervals.empty() || open >= o_.interval / 2));
  }

  void close_interval(double now) {
    const double rate = open_.stepping > 0 ? double(setup_.bodies) * double(open_.steps) / open_.stepping : 0;
    out_.intervals.push_back({now, open_.steps, rate, memory_now().resident});
    for (std::size_t k = 0; k < setup_.groups.size(); ++k) conservation_update(setup_.groups[k], conservation_[k]);
    if (!o_.quiet && ::isatty(STDERR_FILENO) != 1) print_line(out_.intervals.back());
    open_ = {now, 0, 0};
  }

  // Without a terminal (a log), a line per interval instead of the progress bar.
  void print_line(const Interval& i) const {
    std::fprintf(stderr, "kinema stress: %.1f s, step %llu: %.4g body-steps/s, %.1f MiB resident\n",
                 i.end_seconds, static_cast<unsigned long long>(out_.done), i.body_steps_per_second,
                 mib(i.resident));
  }

  struct OpenInterval {
    double start = 0;  // seconds since the stepping started
    double stepping = 0;
    std::uint64_t steps = 0;
  };

  void save_checkpoint() {
    out_.elapsed_seconds = seconds_since(start_);
    CheckpointWriter out;
    for (const auto& g : setup_.groups) g.save(out);
    out.set_user_data(encode(stress_record(fingerprint_, out_, conservation_)));
    out.save(o_.checkpoint.path);
    ++out_.checkpoints;
  }

  const StressOptions& o_;
  StressSetup<T>& setup_;
  std::vector<Conservation<T>>& conservation_;
  Clock::time_point start_;
  OpenInterval open_;
  StressOutcome out_;
  std::string fingerprint_;
  CheckpointTimer checkpoints_;
};

template <class T>
Json group_report(const StressGroup<T>& g, const Conservation<T>& c) {
  Json j;
  j["name"] = g.name();
  j["bodies"] = g.size();
  j["kind"] = g.rigid() ? "rigid" : "particles";
  j["path"] = g.stepper().fused() ? "fused" : "staged";
  if (g.conserves_energy()) j["energy_drift"] = {{"final", c.energy.last}, {"worst", c.energy.worst}};
  if (g.conserves_momentum()) j["momentum_drift"] = {{"final", c.momentum.last}, {"worst", c.momentum.worst}};
  return j;
}

template <class T>
Json memory_report(const StressSetup<T>& setup, const StressOutcome& out, const Memory& at_start) {
  double state = 0, scratch = 0;
  for (const auto& g : setup.groups) state += double(g.state_bytes()), scratch += double(g.stepper().scratch_bytes());
  const Memory m = memory_now();
  Json j;
  j["state_bytes"] = state;
  j["scratch_bytes"] = scratch;
  j["resident_at_start_bytes"] = at_start.resident;
  j["peak_resident_bytes"] = m.peak;
  j["peak_over_state_and_scratch"] = m.peak / (state + scratch);
  if (!out.intervals.empty()) {
    j["resident_first_interval_bytes"] = out.intervals.front().resident;
    j["resident_last_interval_bytes"] = out.intervals.back().resident;
  }
  return j;
}

// Where a group stopped being finite, for stderr and the report's error.
std::string failure_text(const Failure& f) {
  const std::string steps = f.first == f.last
      ? "at step " + std::to_string(f.last)
      : "between steps " + std::to_string(f.first) + " and " + std::to_string(f.last);
  return "group " + f.group + " is no longer finite " + steps + ": body " + std::to_string(f.body) + ", " + f.field;
}

Json failure_report(const Failure& f, FiniteGuard guard) {
  Json where;
  where["group"] = f.group;
  if (f.first == f.last) where["step"] = f.last;
  else where["between_steps"] = {f.first, f.last};
  where.update({{"body", f.body}, {"field", f.field}});
  if (guard != FiniteGuard::off) where["state_kept_at_step"] = f.last - 1;
  return where;
}

Json intervals_report(const std::vector<Interval>& intervals) {
  Json j = Json::array();
  for (const Interval& i : intervals) {
    j.push_back({{"end_seconds", i.end_seconds}, {"steps", i.steps},
                 {"body_steps_per_second", i.body_steps_per_second}, {"resident_bytes", i.resident}});
  }
  return j;
}

// The digest of a checkpoint of every group: equal values, equal bits (states and clocks).
template <class T>
std::string state_crc(const std::vector<StressGroup<T>>& groups) {
  CheckpointWriter state;
  for (const auto& g : groups) g.save(state);
  return crc_text(state.digest());
}

template <class T>
Json stress_report(const StressOptions& o, const StressSetup<T>& setup, const std::vector<Conservation<T>>& conservation,
                   const StressOutcome& out, const Memory& at_start) {
  const Stepper<T>& s = setup.groups.front().stepper();
  Json j;
  j["scene"] = setup.name;
  j["bodies"] = setup.bodies;
  j["method"] = std::string(s.method().name);
  j["precision"] = std::string(precision_name(sizeof(T) == 4 ? Precision::single : Precision::dual));
  j["isa"] = std::string(isa_name(s.isa()));
  j["threads"] = s.threads();
  j["guard"] = guard_name(o.guard);
  j["dt"] = setup.dt;
  j["steps"] = out.done;  // completed by every group
  j["wall_seconds"] = number(measured(out.stepping_seconds));
  j["body_steps_per_second"] =
      number(out.stepping_seconds > 0 ? measured(double(setup.bodies) * double(out.done) / out.stepping_seconds) : 0.0);
  j["throughput"] = throughput_report(out.intervals);
  j["memory"] = memory_report(setup, out, at_start);
  j["groups"] = Json::array();
  for (std::size_t k = 0; k < setup.groups.size(); ++k) j["groups"].push_back(group_report(setup.groups[k], conservation[k]));
  j["finite"] = !out.failure;
  if (out.failure) j["first_non_finite"] = failure_report(*out.failure, o.guard);
  if (interrupting_signal() != 0 && !out.failure) j["interrupted"] = signal_name(interrupting_signal());
  j["complete"] = !out.failure && interrupting_signal() == 0;
  if (out.failure) {
    j["error"] = failure_text(*out.failure);
  } else if (interrupting_signal() != 0) {
    j["error"] = "stopped by " + signal_name(interrupting_signal());
  }
  if (out.resumed_at) j["resumed_from"] = {{"checkpoint", o.checkpoint.resume_path}, {"step", *out.resumed_at}};
  if (!o.checkpoint.path.empty()) j["checkpoints_written"] = out.checkpoints;
  j["state_crc32c"] = state_crc(setup.groups);
  j["intervals"] = intervals_report(out.intervals);
  return j;
}

std::string text_of(const Json& value) {
  return printable(value.is_string() ? value.get<std::string>() : value.dump());
}

void print_throughput(const Json& t) {
  if (!t.contains("median")) return;
  std::printf("  %-22s min %.4g, median %.4g, max %.4g body-steps/s over %zu intervals", "throughput",
              t["min"].get<double>(), t["median"].get<double>(), t["max"].get<double>(),
              t["intervals"].get<std::size_t>());
  if (t.contains("last_quarter_over_first")) {
    std::printf("; last quarter / first %.3f", t["last_quarter_over_first"].get<double>());
  }
  std::printf("\n");
}

void print_memory(const Json& m) {
  std::printf("  %-22s peak %.1f MiB = %.3f x (state %.1f MiB + scratch %.1f MiB)\n", "memory",
              mib(m["peak_resident_bytes"]), m["peak_over_state_and_scratch"].get<double>(),
              mib(m["state_bytes"]), mib(m["scratch_bytes"]));
}

void print_group(const Json& g) {
  std::printf("  group %-16s %zu %s, %s", g["name"].get<std::string>().c_str(), g["bodies"].get<std::size_t>(),
              g["kind"].get<std::string>().c_str(), g["path"].get<std::string>().c_str());
  for (const char* drift : {"energy_drift", "momentum_drift"}) {
    if (g.contains(drift)) std::printf(", %s %.3g (worst %.3g)", drift, g[drift]["final"].get<double>(), g[drift]["worst"].get<double>());
  }
  std::printf("\n");
}

void print_report(const Json& j) {
  std::printf("kinema stress: %s\n", printable(j["scene"].get<std::string>()).c_str());
  for (const char* key : {"bodies", "method", "precision", "isa", "threads", "guard", "dt", "steps",
                          "wall_seconds", "body_steps_per_second", "finite"}) {
    std::printf("  %-22s %s\n", key, text_of(j[key]).c_str());
  }
  print_throughput(j["throughput"]);
  print_memory(j["memory"]);
  for (const Json& g : j["groups"]) print_group(g);
  if (j.contains("first_non_finite")) std::printf("  %-22s %s\n", "first_non_finite", j["first_non_finite"].dump().c_str());
}

// The exit code, with a line on stderr when the run did not end as asked.
int stress_exit_code(const StressOptions& o, const StressOutcome& out) {
  if (const auto& f = out.failure) {
    std::fprintf(stderr, "kinema: error: %s%s\n", failure_text(*f).c_str(),
                 o.guard == FiniteGuard::off ? "" : " (the state before that step is kept)");
    return 3;
  }
  if (const int signal = interrupting_signal()) {
    std::fprintf(stderr, "kinema: stopped by %s after step %llu%s\n", signal_name(signal).c_str(),
                 static_cast<unsigned long long>(out.done),
                 o.report_path.empty() ? "" : "; the report is complete to there");
    return 128 + signal;
  }
  return 0;
}

// The report of a run an error ended; its own failure is not the error to report.
void write_failure(ReportFile& report, const Json& j) {
  try {
    report.write(j);
  } catch (const std::exception&) {
  }
}

template <class T>
int run_stress(const StressOptions& o, const Scene* scene) {
  const Memory at_start = memory_now();  // before any body is built
  ReportFile report(o.report_path, "report");  // a path that cannot be written: refused now
  const std::string name = scene ? scene->name : "random (seed " + std::to_string(o.seed) + ")";
  StressSetup<T> setup;
  try {
    setup = set_up<T>(o, scene);
  } catch (const std::exception& e) {
    write_failure(report, Json{{"scene", name}, {"steps", 0}, {"complete", false}, {"error", e.what()}});
    throw;
  }
  std::vector<Conservation<T>> conservation;
  for (const auto& g : setup.groups) conservation.push_back(conservation_start(g));
  StressOutcome out;
  try {
    // Read once, before any step, and only for checkpoints (it reads the scene file again).
    const Precision precision = sizeof(T) == 4 ? Precision::single : Precision::dual;
    const std::string method(setup.groups.front().stepper().method().name);
    const std::string fingerprint = o.checkpoint.wanted() ? stress_fingerprint(o, method, precision, setup.dt) : "";
    StressOutcome resumed;
    if (!o.checkpoint.resume_path.empty()) {
      resumed = resume_stress(o.checkpoint.resume_path, fingerprint, setup.groups, conservation);
    }
    out = StressLoop<T>(o, setup, conservation, std::move(resumed), fingerprint).run();
  } catch (const std::exception& e) {  // a report still says what happened
    write_failure(report, Json{{"scene", setup.name}, {"bodies", setup.bodies}, {"complete", false}, {"error", e.what()}});
    throw;
  }
  // The final drifts are those of the final state, whenever the last interval closed.
  for (std::size_t k = 0; k < setup.groups.size(); ++k) conservation_update(setup.groups[k], conservation[k]);
  const Json j = stress_report(o, setup, conservation, out, at_start);
  report.write(j);
  if (!o.quiet) print_report(j);
  return stress_exit_code(o, out);
}

// The scene file with the command line's overrides, checked.
std::optional<Scene> stress_scene(const StressOptions& o) {
  if (o.scene_path.empty()) return std::nullopt;
  Scene scene = load_scene(o.scene_path);
  if (o.precision) scene.precision = *o.precision;
  if (o.dt) scene.dt = *o.dt;
  if (o.method) scene.method = *o.method;
  check_dt_option(o.dt, scene.precision);  // the option's fault, before the scene's checks blame its dt
  naming_scene(o.scene_path, [&] {
    if (scene.method == "auto") throw Error("stress runs a fixed method: give one with --method");
    method_by_name(scene.method);
    // Neither would act here: refused rather than left silently undone.
    if (!scene.events.empty()) throw Error("stress watches no events: kinema run takes a scene's \"events\"");
    if (scene.rtol || scene.atol) {
      throw Error("stress takes fixed steps of dt: kinema run takes a scene's \"rtol\" and \"atol\"");
    }
    with_precision(scene.precision, [&]<class T>() { check_scene<T>(scene); });
  });
  return scene;
}

void check_fits(const StressOptions& o, Precision precision) {
  const double scalar = precision == Precision::single ? 4 : 8;
  // A method without a fused kernel (bs3, dopri5, rk6) keeps its stages in memory besides.
  const Method* method = o.method ? &method_by_name(*o.method) : nullptr;
  const bool staged = std::ranges::find(staged_methods, method) != staged_methods.end();
  const double stages = staged ? double(method->evaluations()) * 6 + 9 : 0;
  const double need = double(o.bodies) * (kBytesPerBodyPerScalar + stages) * scalar;
  if (need > usable_memory_bytes()) {
    throw Error("--bodies " + std::to_string(o.bodies) + " needs about " + std::to_string(std::uint64_t(mib(need))) +
                " MiB, more than the " + std::to_string(std::uint64_t(mib(usable_memory_bytes()))) +
                " MiB this process may use");
  }
}

}  // namespace

FiniteGuard guard_by_name(const std::string& name) {
  if (name == "off") return FiniteGuard::off;
  if (name == "check") return FiniteGuard::check;
  if (name == "clamp") return FiniteGuard::clamp;
  throw Error("unknown guard '" + printable(name) + "' (off, check, clamp)");
}

namespace {

// What the options ask for, checked before any work.
struct StressPlan {
  std::optional<Scene> scene;
  Precision precision;
};

StressPlan plan_stress(const StressOptions& o) {
  check_distinct({{"--scene", o.scene_path}}, {{"--report", o.report_path}, {"--checkpoint", o.checkpoint.path}});
  check_distinct({{"--resume", o.checkpoint.resume_path}}, {{"--report", o.report_path}});
  if (o.method == "auto") throw Error("stress runs a fixed method; auto is for kinema run");
  if (o.method) method_by_name(*o.method);  // a bad name fails before any work
  const Precision asked = o.precision.value_or(Precision::single);
  if (o.scene_path.empty()) check_dt_option(o.dt, asked);  // a scene's own: in stress_scene
  StressPlan plan{stress_scene(o), Precision::single};
  plan.precision = plan.scene ? plan.scene->precision : asked;
  if (!plan.scene) check_fits(o, plan.precision);
  return plan;
}

}  // namespace

int stress(const StressOptions& o) {
  const StressPlan plan = plan_stress(o);
  const Scene* scene = plan.scene ? &*plan.scene : nullptr;
  return with_precision(plan.precision, [&]<class T>() { return run_stress<T>(o, scene); });
}

void check_stress(const StressOptions& o, std::size_t most_bodies) {
  const StressPlan plan = plan_stress(o);
  const Scene* scene = plan.scene ? &*plan.scene : nullptr;
  if (scene ? evaluation_cost(*scene) > double(most_bodies) : o.bodies > most_bodies) return;
  with_precision(plan.precision, [&]<class T>() { (void)set_up<T>(o, scene); });
}

}  // namespace kinema::cli
