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

// Everything one run needs and produces.
template <class T>
class StressRun {
 public:
  StressRun(const StressOptions& o, const Scene* scene) : o_(o), at_start_(memory_now()) {
    StepperOptions options;
    options.isa = o.isa;
    options.threads = std::min(o.threads == 0 ? hardware_threads() : o.threads, hardware_threads());
    options.guard = o.guard;
    options.max_speed = o.max_speed, options.max_angular_speed = o.max_angular_speed;
    const Method& method = method_by_name(scene ? scene->method : o.method.value_or("rk4"));
    groups_ = scene ? scene_stress_groups<T>(*scene, method, options)
                    : random_stress_groups<T>(o.bodies, o.seed, method, options);
    if (groups_.empty()) throw Error("the scene has no bodies");
    dt_ = o.dt ? *o.dt : scene ? scene->dt : kStressDt;
    h_ = T(dt_);
    for (const auto& g : groups_) {
      g.stepper().check_step_size(h_);
      bodies_ += g.size();
    }
    name_ = scene ? scene->name : "random (seed " + std::to_string(o.seed) + ")";
    steps_ = o.seconds ? std::numeric_limits<std::uint64_t>::max()
                       : o.steps ? *o.steps : scene ? scene->steps : 1000;
  }

  int run() {
    ReportFile report(o_.report_path, "report");
    for (const auto& g : groups_) conservation_.push_back(conservation_start(g));
    step_until_done();
    // The final drifts are those of the final state, whenever the last interval closed.
    for (std::size_t k = 0; k < groups_.size(); ++k) conservation_update(groups_[k], conservation_[k]);
    const Json summary = summarize();
    report.write(summary);
    if (!o_.quiet) print(summary);
    return exit_code();
  }

 private:
  void step_until_done() {
    Progress progress("kinema stress", o_.quiet);
    const bool lines = !o_.quiet && ::isatty(STDERR_FILENO) != 1;
    const auto start = Clock::now();
    std::uint64_t chunk = 1, interval_steps = 0;
    double interval_stepping = 0, interval_start = 0;
    while (!finished(start) && !failure_ && interrupting_signal() == 0) {
      const std::uint64_t n = std::min(chunk, steps_ - done_);
      const auto t0 = Clock::now();
      advance(n);
      const double took = seconds_since(t0);
      stepping_seconds_ += took, interval_stepping += took, interval_steps += n;
      chunk = std::clamp<std::uint64_t>(std::uint64_t(kChunkSeconds * double(n) / std::max(took, 1e-9)), 1, 2 * n);
      const double now = seconds_since(start);
      const bool last = finished(start) || failure_ || interrupting_signal() != 0;
      if (now - interval_start >= o_.interval || (last && (intervals_.empty() || now - interval_start >= o_.interval / 2))) {
        close_interval(now, interval_steps, interval_stepping);
        if (lines) print_line(intervals_.back());
        interval_start = now, interval_steps = 0, interval_stepping = 0;
      }
      progress.update(o_.seconds ? std::min(1.0, now / *o_.seconds) : double(done_) / double(steps_));
    }
    progress.finish();
  }

  bool finished(Clock::time_point start) const {
    return done_ >= steps_ || (o_.seconds && seconds_since(start) >= *o_.seconds);
  }

  // n steps of every group; under a guard a group that fails stops at its last finite step.
  void advance(std::uint64_t n) {
    for (auto& g : groups_) {
      try {
        g.advance(h_, n);
      } catch (const NonFiniteError& e) {
        failure_ = Failure{g.name(), e.body, e.field, done_ + e.step, done_ + e.step};
        return;
      }
      if (o_.guard == FiniteGuard::off) {
        if (const auto bad = g.first_non_finite()) {
          failure_ = Failure{g.name(), bad->body, bad->field, done_ + 1, done_ + n};
          return;
        }
      }
    }
    done_ += n;
  }

  void close_interval(double now, std::uint64_t steps, double stepping) {
    const double rate = stepping > 0 ? double(bodies_) * double(steps) / stepping : 0;
    intervals_.push_back({now, steps, rate, memory_now().resident});
    for (std::size_t k = 0; k < groups_.size(); ++k) conservation_update(groups_[k], conservation_[k]);
  }

  void print_line(const Interval& i) const {
    std::fprintf(stderr, "kinema stress: %.1f s, step %llu: %.4g body-steps/s, %.1f MiB resident\n",
                 i.end_seconds, static_cast<unsigned long long>(done_), i.body_steps_per_second,
                 mib(i.resident));
  }

  Json group_report(std::size_t k) const {
    const StressGroup<T>& g = groups_[k];
    Json j;
    j["name"] = g.name();
    j["bodies"] = g.size();
    j["kind"] = g.rigid() ? "rigid" : "particles";
    j["path"] = g.stepper().fused() ? "fused" : "staged";
    if (g.conserves_energy()) {
      j["energy_drift"] = {{"final", conservation_[k].energy.last}, {"worst", conservation_[k].energy.worst}};
    }
    if (g.conserves_momentum()) {
      j["momentum_drift"] = {{"final", conservation_[k].momentum.last},
                             {"worst", conservation_[k].momentum.worst}};
    }
    return j;
  }

  Json memory_report() const {
    double state = 0, scratch = 0;
    for (const auto& g : groups_) state += double(g.state_bytes()), scratch += double(g.stepper().scratch_bytes());
    const Memory m = memory_now();
    Json j;
    j["state_bytes"] = state;
    j["scratch_bytes"] = scratch;
    j["resident_at_start_bytes"] = at_start_.resident;
    j["peak_resident_bytes"] = m.peak;
    j["peak_over_state_and_scratch"] = m.peak / (state + scratch);
    if (!intervals_.empty()) {
      j["resident_first_interval_bytes"] = intervals_.front().resident;
      j["resident_last_interval_bytes"] = intervals_.back().resident;
    }
    return j;
  }

  Json summarize() const {
    const Stepper<T>& s = groups_.front().stepper();
    Json j;
    j["scene"] = name_;
    j["bodies"] = bodies_;
    j["method"] = std::string(s.method().name);
    j["precision"] = std::string(precision_name(sizeof(T) == 4 ? Precision::single : Precision::dual));
    j["isa"] = std::string(isa_name(s.isa()));
    j["threads"] = s.threads();
    j["guard"] = guard_name(o_.guard);
    j["dt"] = dt_;
    j["steps"] = done_;  // completed by every group
    j["wall_seconds"] = stepping_seconds_;
    j["body_steps_per_second"] = stepping_seconds_ > 0 ? double(bodies_) * double(done_) / stepping_seconds_ : 0.0;
    j["throughput"] = throughput_report(intervals_);
    j["memory"] = memory_report();
    j["groups"] = Json::array();
    for (std::size_t k = 0; k < groups_.size(); ++k) j["groups"].push_back(group_report(k));
    j["finite"] = !failure_;
    if (failure_) {
      Json& where = j["first_non_finite"];
      where["group"] = failure_->group;
      if (failure_->first == failure_->last) where["step"] = failure_->last;
      else where["between_steps"] = {failure_->first, failure_->last};
      where.update({{"body", failure_->body}, {"field", failure_->field}});
      if (o_.guard != FiniteGuard::off) where["state_kept_at_step"] = failure_->last - 1;
    }
    if (interrupting_signal() != 0 && !failure_) j["interrupted"] = signal_name(interrupting_signal());
    j["intervals"] = Json::array();
    for (const Interval& i : intervals_) {
      j["intervals"].push_back({{"end_seconds", i.end_seconds}, {"steps", i.steps},
                                {"body_steps_per_second", i.body_steps_per_second},
                                {"resident_bytes", i.resident}});
    }
    return j;
  }

  void print(const Json& j) const {
    std::printf("kinema stress: %s\n", printable(j["scene"].get<std::string>()).c_str());
    for (const char* key : {"bodies", "method", "precision", "isa", "threads", "guard", "dt", "steps",
                            "wall_seconds", "body_steps_per_second", "finite"}) {
      std::printf("  %-22s %s\n", key, printable(j[key].is_string() ? j[key].get<std::string>() : j[key].dump()).c_str());
    }
    const Json& t = j["throughput"];
    if (t.contains("median")) {
      std::printf("  %-22s min %.4g, median %.4g, max %.4g body-steps/s over %zu intervals", "throughput",
                  t["min"].get<double>(), t["median"].get<double>(), t["max"].get<double>(),
                  t["intervals"].get<std::size_t>());
      if (t.contains("last_quarter_over_first")) {
        std::printf("; last quarter / first %.3f", t["last_quarter_over_first"].get<double>());
      }
      std::printf("\n");
    }
    const Json& m = j["memory"];
    std::printf("  %-22s peak %.1f MiB = %.3f x (state %.1f MiB + scratch %.1f MiB)\n", "memory",
                mib(m["peak_resident_bytes"]), m["peak_over_state_and_scratch"].get<double>(),
                mib(m["state_bytes"]), mib(m["scratch_bytes"]));
    for (const Json& g : j["groups"]) {
      std::printf("  group %-16s %zu %s, %s", g["name"].get<std::string>().c_str(), g["bodies"].get<std::size_t>(),
                  g["kind"].get<std::string>().c_str(), g["path"].get<std::string>().c_str());
      for (const char* drift : {"energy_drift", "momentum_drift"}) {
        if (g.contains(drift)) std::printf(", %s %.3g (worst %.3g)", drift, g[drift]["final"].get<double>(), g[drift]["worst"].get<double>());
      }
      std::printf("\n");
    }
    if (j.contains("first_non_finite")) std::printf("  %-22s %s\n", "first_non_finite", j["first_non_finite"].dump().c_str());
  }

  int exit_code() const {
    if (failure_) {
      const std::string steps = failure_->first == failure_->last
          ? "at step " + std::to_string(failure_->last)
          : "between steps " + std::to_string(failure_->first) + " and " + std::to_string(failure_->last);
      std::fprintf(stderr, "kinema: error: group %s is no longer finite %s: body %zu, %s%s\n",
                   failure_->group.c_str(), steps.c_str(), failure_->body, failure_->field.c_str(),
                   o_.guard == FiniteGuard::off ? "" : " (the state before that step is kept)");
      return 3;
    }
    if (const int signal = interrupting_signal()) {
      std::fprintf(stderr, "kinema: stopped by %s after step %llu; the report is complete to there\n",
                   signal_name(signal).c_str(), static_cast<unsigned long long>(done_));
      return 128 + signal;
    }
    return 0;
  }

  const StressOptions& o_;
  Memory at_start_;
  std::vector<StressGroup<T>> groups_;
  std::vector<Conservation<T>> conservation_;
  std::string name_;
  double dt_ = 0;
  T h_ = 0;
  std::size_t bodies_ = 0;
  std::uint64_t steps_ = 0, done_ = 0;
  double stepping_seconds_ = 0;
  std::vector<Interval> intervals_;
  std::optional<Failure> failure_;
};

// The scene file with the command line's overrides, checked.
std::optional<Scene> stress_scene(const StressOptions& o) {
  if (o.scene_path.empty()) return std::nullopt;
  Scene scene = load_scene(o.scene_path);
  if (o.precision) scene.precision = *o.precision;
  if (o.dt) scene.dt = *o.dt;
  if (o.method) scene.method = *o.method;
  try {
    if (scene.method == "auto") throw Error("stress runs a fixed method: give one with --method");
    method_by_name(scene.method);
    with_precision(scene.precision, [&]<class T>() { check_scene<T>(scene); });
  } catch (const Error& e) {
    throw Error(o.scene_path + ": " + e.what());
  }
  return scene;
}

void check_fits(const StressOptions& o, Precision precision) {
  const double scalar = precision == Precision::single ? 4 : 8;
  const double need = double(o.bodies) * kBytesPerBodyPerScalar * scalar;
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

int stress(const StressOptions& o) {
  if (o.method == "auto") throw Error("stress runs a fixed method; auto is for kinema run");
  if (o.method) method_by_name(*o.method);  // a bad name fails before any work
  const std::optional<Scene> scene = stress_scene(o);
  const Precision precision = scene ? scene->precision : o.precision.value_or(Precision::single);
  if (!scene) check_fits(o, precision);
  return with_precision(precision, [&]<class T>() {
    StressRun<T> run(o, scene ? &*scene : nullptr);
    return run.run();
  });
}

}  // namespace kinema::cli
