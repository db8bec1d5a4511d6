#include "run_command.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>

#include <nlohmann/json.hpp>

#include "interrupt.hpp"
#include "kinema/scenes.hpp"
#include "kinema/stability.hpp"
#include "progress.hpp"
#include "report_file.hpp"
#include "trajectory.hpp"

namespace kinema::cli {
namespace {

using Clock = std::chrono::steady_clock;

// Body-steps per advance call when nothing else bounds it: long enough that the
// finiteness check after each call costs little, short enough (tens of milliseconds) that
// a signal is answered at once.
constexpr double kBodyStepsPerChunk = double(1 << 26);

}  // namespace

Scene scene_with_overrides(const RunOptions& o) {
  Scene scene = load_scene(o.scene_path);
  if (o.method) scene.method = *o.method;
  if (o.tolerance) scene.tolerance = *o.tolerance;
  if (o.dt) scene.dt = *o.dt;
  if (o.steps) scene.steps = *o.steps;
  if (o.precision) scene.precision = *o.precision;
  if (o.rtol) scene.rtol = *o.rtol;
  if (o.atol) scene.atol = *o.atol;
  if (scene.method != "auto") method_by_name(scene.method);
  try {
    if (scene.method == "auto" && !scene.tolerance) {
      throw Error("method auto needs a tolerance (the scene's \"tolerance\" or --tolerance)");
    }
    if ((scene.rtol || scene.atol) && (scene.method == "auto" || method_by_name(scene.method).embedded_order == 0)) {
      throw Error("rtol and atol control the steps of a method with an embedded pair (bs3, dopri5), not " +
                  scene.method);
    }
    if ((scene.rtol || scene.atol) && (!scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid))) {
      throw Error("rtol and atol control the steps of particles; the scene has rigid bodies");
    }
    with_precision(scene.precision, [&]<class T>() { check_scene<T>(scene); });
  } catch (const Error& e) {
    throw Error(o.scene_path + ": " + e.what());
  }
  return scene;
}

namespace {

void print_summary(const nlohmann::ordered_json& summary) {
  std::printf("kinema run: %s\n", printable(summary["scene"].get<std::string>()).c_str());
  for (const auto& [key, value] : summary.items()) {
    if (key == "scene") continue;
    std::printf("  %-22s %s\n", key.c_str(),
                printable(value.is_string() ? value.get<std::string>() : value.dump()).c_str());
  }
}

// Where the state first stopped being finite: at step `last` (and `first` == `last`) when
// found exactly, else somewhere in [first, last].
struct BlowUp {
  std::uint64_t first, last;
  double t;          // at `last`
  std::size_t body;  // particles first, then rigid bodies
  std::string field;
};

// A replay of the run to find the exact step is skipped past this many body-steps, or when
// a second copy of the state would not fit in memory.
constexpr double kReplayBodySteps = double(std::uint64_t(1) << 32);

template <class T>
std::optional<NonFinite> first_non_finite(const World<T>& world) {
  if (auto p = kinema::first_non_finite(world.particles)) return p;
  if (auto r = kinema::first_non_finite(world.rigid)) {
    return NonFinite{world.particles.size() + r->body, r->field};
  }
  return std::nullopt;
}

// The run went non-finite in steps (from, from + n]: `world` is at from + n. Steps a fresh
// world to `from`, then one step at a time (results do not depend on how steps are grouped,
// so this finds the very step), unless that would cost too much or a signal comes.
template <class T>
BlowUp find_blow_up(const Scene& scene, const StepperOptions& options, const World<T>& world,
                    std::uint64_t from, std::uint64_t n) {
  const NonFinite at_end = *first_non_finite(world);
  BlowUp range{from + 1, from + n, world.time(), at_end.body, at_end.field};
  const double bodies = double(world.particles.size() + world.rigid.size());
  if (double(from + n) * bodies > kReplayBodySteps ||
      2 * state_bytes<T>(scene) > usable_memory_bytes()) {
    return range;
  }
  World<T> replay(scene, method_by_name(scene.method), options);
  const T h = T(scene.dt);
  if (from > 0) replay.advance(h, from);
  for (std::uint64_t step = from + 1; step <= from + n && interrupting_signal() == 0; ++step) {
    replay.advance(h, 1);
    if (auto bad = first_non_finite(replay)) return {step, step, replay.time(), bad->body, bad->field};
  }
  return range;
}

// The scene's error control, if any: with one of rtol and atol given, the other is the same.
std::optional<Tolerances> tolerances_of(const Scene& scene) {
  if (!scene.rtol && !scene.atol) return std::nullopt;
  Tolerances t;
  t.rtol = scene.rtol.value_or(*scene.atol);
  t.atol = scene.atol.value_or(*scene.rtol);
  return t;
}

// Error-controlled steps to t, each call starting from the size the last one proposed.
template <class T>
void advance_adaptive(World<T>& world, double t, Tolerances tolerances, AdaptiveStats& total) {
  tolerances.initial_step = total.next_step;
  const AdaptiveStats s = world.advance_to(t, tolerances);
  total.smallest_step = total.accepted == 0 ? s.smallest_step
                        : s.accepted == 0   ? total.smallest_step
                                            : std::min(total.smallest_step, s.smallest_step);
  total.largest_step = std::max(total.largest_step, s.largest_step);
  total.accepted += s.accepted, total.rejected += s.rejected, total.evaluations += s.evaluations;
  if (s.next_step > 0) total.next_step = s.next_step;
}

// The stiffness of the scene at its start, in double whatever the run's precision (finite
// differences in float lose half their digits): on the particles, else the rigid bodies'
// centres; on 1024 of them spread evenly when only local terms act (each body is then a
// system of its own, and the stiffest of a sample stands for the rest).
// 40 Jacobian products (57 force evaluations) on the run's threads: a few tenths of a second
// for the 4096-body cluster.
StiffnessEstimate stiffness_at_start(const Scene& scene, const StepperOptions& options) {
  const ForceModel<double> forces = make_forces<double>(scene);
  const bool sampled = forces.fusable();
  const Scene source = sampled ? sample_bodies(scene, 1024) : scene;
  ParticleSet<double> bodies = make_particles<double>(source);
  if (bodies.size() == 0) bodies = make_rigid_bodies<double>(source).centers();
  return estimate_stiffness(bodies, forces, 0, 40, options);
}

std::string mode_name(const StiffnessEstimate& e) {
  return e.angle < 0.3 ? "damping" : e.angle > 1.27 ? "oscillation" : "damped oscillation";
}

// Warns (or with --strict refuses) when dt is past the method's largest stable step and the
// fastest mode grows more than twofold over the run (a weak instability, such as midpoint's
// on an oscillation, that a run never shows is left alone).
void check_stable_step(const Scene& scene, const RunOptions& o, const StiffnessEstimate& e, double stable) {
  if (!(scene.dt > stable)) return;
  const double log_growth = double(scene.steps) * std::log(growth_per_step(method_by_name(scene.method), e, scene.dt));
  if (!(log_growth > std::log(2.0))) return;
  char text[400];
  std::snprintf(text, sizeof text,
                "dt %g is past the largest stable step of %s on this scene, %.3g: its fastest mode (%s at "
                "|lambda| = %.4g /s) grows %.3g-fold over the run",
                scene.dt, scene.method.c_str(), stable, mode_name(e).c_str(), e.magnitude,
                std::exp(std::min(log_growth, 700.0)));
  if (o.strict) throw Error(o.scene_path + ": " + text + " (--strict)");
  if (!o.quiet) std::fprintf(stderr, "kinema: warning: %s\n", printable(text).c_str());
}

// What happened before stepping that the summary reports.
struct RunContext {
  std::optional<nlohmann::ordered_json> auto_choice;
};

StepperOptions stepper_options(const RunOptions& o) {
  StepperOptions options;
  options.isa = o.isa;
  // More threads than the machine has would only wait on each other (and make oneTBB warn).
  options.threads = std::min(o.threads == 0 ? hardware_threads() : o.threads, hardware_threads());
  options.relaxed_fma = o.relaxed_fma;
  return options;
}

template <class T>
World<T> build_world(const Scene& scene, const RunOptions& o, const StepperOptions& options) {
  try {
    return World<T>(scene, method_by_name(scene.method), options);
  } catch (const Error& e) {  // bodies or forces the precision cannot hold: name the file
    throw Error(o.scene_path + ": " + e.what());
  }
}

template <class T>
std::size_t body_count(const World<T>& world) {
  return world.particles.size() + world.rigid.size();
}

// What the run knows about its steps before the first: the scene's stiffness at the start,
// the method's largest stable step there, and the error control if any.
struct StepPlan {
  StiffnessEstimate stiffness;
  double stable_step = 0;
  std::optional<Tolerances> tolerances;
};

StepPlan plan_steps(const Scene& scene, const RunOptions& o, const StepperOptions& options) {
  StepPlan plan;
  plan.stiffness = stiffness_at_start(scene, options);
  plan.stable_step = largest_stable_step(method_by_name(scene.method), plan.stiffness);
  plan.tolerances = tolerances_of(scene);
  // Error control never goes past the stable step; fixed steps are checked against it.
  if (plan.tolerances && plan.stable_step > 0) plan.tolerances->max_step = plan.stable_step;
  if (!plan.tolerances) check_stable_step(scene, o, plan.stiffness, plan.stable_step);
  return plan;
}

// Steps per advance call: for the progress bar, the trajectory and signals (the same bits as
// one call). Error-controlled steps land on each call's end, so their calls are longer: a
// sixteenth of the run or more.
std::uint64_t steps_per_call(const Scene& scene, std::size_t bodies, bool adaptive) {
  const auto bounded = std::uint64_t(std::max(1.0, kBodyStepsPerChunk / double(std::max<std::size_t>(bodies, 1))));
  return adaptive ? std::max<std::uint64_t>({1, scene.steps / 16, bounded})
                  : std::min<std::uint64_t>(std::max<std::uint64_t>(1, scene.steps / 100), bounded);
}

// What stepping did.
struct Stepped {
  std::uint64_t done = 0;   // steps of dt completed (error control: their span)
  double wall_seconds = 0;  // stepping only: loading, checking and writing are not timed
  std::optional<BlowUp> blow_up;
  AdaptiveStats adaptive;
};

// Steps from `done` to done + n (error control: over that span), timed.
template <class T>
void advance_timed(World<T>& world, const Scene& scene, const std::optional<Tolerances>& tolerances,
                   std::uint64_t n, Stepped& s) {
  const auto start = Clock::now();
  if (tolerances) {
    advance_adaptive(world, double(s.done + n) * scene.dt, *tolerances, s.adaptive);
  } else {
    world.advance(T(scene.dt), n);
  }
  s.wall_seconds += std::chrono::duration<double>(Clock::now() - start).count();
}

// Every K-th step, the last, and the one that stopped being finite.
bool trajectory_due(const Scene& scene, const RunOptions& o, std::uint64_t done, bool finite) {
  return done % o.every == 0 || done == scene.steps || !finite;
}

template <class T>
Stepped step_scene(World<T>& world, const Scene& scene, const RunOptions& o, const StepperOptions& options,
                   const std::optional<Tolerances>& tolerances, std::optional<TrajectoryWriter>& trajectory) {
  const std::uint64_t chunk = steps_per_call(scene, body_count(world), tolerances.has_value());
  Progress progress("kinema run", o.quiet);
  Stepped s;
  if (trajectory) trajectory->write(0, world.time(), world.particles, world.rigid);
  while (s.done < scene.steps && interrupting_signal() == 0) {
    std::uint64_t n = std::min(chunk, scene.steps - s.done);
    if (trajectory) n = std::min(n, o.every - s.done % o.every);  // stop at each K-th step
    advance_timed(world, scene, tolerances, n, s);
    const bool finite = world.finite();
    if (!finite) s.blow_up = find_blow_up<T>(scene, options, world, s.done, n);
    s.done += n;
    progress.update(double(s.done) / double(scene.steps));
    if (trajectory && trajectory_due(scene, o, s.done, finite)) {
      trajectory->write(s.done, world.time(), world.particles, world.rigid);
    }
    if (!finite) break;
  }
  if (trajectory) trajectory->close();
  progress.finish();
  return s;
}

// What ran: the scene, the bodies, the method and where it ran.
template <class T>
void describe_setup(nlohmann::ordered_json& summary, const World<T>& world, const Scene& scene,
                    const RunOptions& o, const Stepped& s) {
  const Stepper<T>& stepper = world.main_stepper();
  summary["scene"] = scene.name;
  summary["bodies"] = body_count(world);
  summary["particles"] = world.particles.size();
  summary["rigid_bodies"] = world.rigid.size();
  summary["steps"] = s.done;
  summary["method"] = std::string(stepper.method().name);
  summary["path"] = stepper.fused() ? "fused" : "staged";
  summary["dt"] = scene.dt;
  summary["t_final"] = world.time();
  summary["precision"] = std::string(precision_name(scene.precision));
  summary["isa"] = std::string(isa_name(stepper.isa()));
  summary["relaxed_fma"] = o.relaxed_fma;
  summary["threads"] = stepper.threads();
  summary["workers_used"] = stepper.chosen_workers();  // what the measurements favoured (0: the calling thread)
}

void describe_error_control(nlohmann::ordered_json& summary, const Tolerances& tolerances, const AdaptiveStats& a) {
  summary["rtol"] = tolerances.rtol;
  summary["atol"] = tolerances.atol;
  summary["accepted_steps"] = a.accepted;
  summary["rejected_steps"] = a.rejected;
  summary["smallest_step"] = a.smallest_step;
  summary["largest_step"] = a.largest_step;
}

// The stiffness, the work done, its speed and the energy.
template <class T>
void describe_cost(nlohmann::ordered_json& summary, const World<T>& world, const StepPlan& plan, const Stepped& s,
                   double initial_energy) {
  summary["stiffness"] = plan.stiffness.magnitude;
  if (std::isfinite(plan.stable_step)) summary["largest_stable_step"] = plan.stable_step;
  summary["force_evaluations"] = plan.tolerances ? s.adaptive.evaluations
                                                 : s.done * std::uint64_t(world.main_stepper().method().evaluations());
  summary["wall_seconds"] = s.wall_seconds;
  summary["body_steps_per_second"] =
      s.wall_seconds > 0 ? double(body_count(world)) * double(s.done) / s.wall_seconds : 0.0;
  summary["energy_initial"] = initial_energy;
  summary["energy_final"] = world.total_energy();
}

void describe_end(nlohmann::ordered_json& summary, const Scene& scene, const Stepped& s) {
  summary["finite"] = !s.blow_up;
  if (s.blow_up) {
    auto& where = summary["first_non_finite"];
    if (s.blow_up->first == s.blow_up->last) {
      where["step"] = s.blow_up->last;
    } else {
      where["between_steps"] = {s.blow_up->first, s.blow_up->last};
    }
    where.update({{"t", s.blow_up->t}, {"body", s.blow_up->body}, {"field", s.blow_up->field}});
  }
  const int signal = interrupting_signal();
  if (signal != 0 && s.done < scene.steps) {
    summary["interrupted"] = signal_name(signal);
    summary["steps_requested"] = scene.steps;
  }
}

template <class T>
nlohmann::ordered_json summarize(const World<T>& world, const Scene& scene, const RunOptions& o,
                                 const StepPlan& plan, const Stepped& s, double initial_energy,
                                 const RunContext& context) {
  nlohmann::ordered_json summary;
  describe_setup(summary, world, scene, o, s);
  if (plan.tolerances) describe_error_control(summary, *plan.tolerances, s.adaptive);
  describe_cost(summary, world, plan, s, initial_energy);
  describe_end(summary, scene, s);
  if (context.auto_choice) summary["auto"] = *context.auto_choice;
  return summary;
}

void report_blow_up(const BlowUp& b) {
  const std::string steps = b.first == b.last
      ? "after step " + std::to_string(b.last)
      : "between steps " + std::to_string(b.first) + " and " + std::to_string(b.last);
  std::fprintf(stderr,
               "kinema: error: the state is no longer finite %s (t = %g): body %zu, %s (try a "
               "smaller dt or a more stable method)\n",
               steps.c_str(), b.t, b.body, b.field.c_str());
}

// The exit code, with a line on stderr when the run did not end as asked.
int finish(const nlohmann::ordered_json& summary, const Scene& scene, const Stepped& s) {
  if (s.blow_up) {
    report_blow_up(*s.blow_up);
    return 3;
  }
  if (summary.contains("interrupted")) {
    const int signal = interrupting_signal();
    std::fprintf(stderr, "kinema: stopped by %s after step %llu of %llu; outputs are complete to there\n",
                 signal_name(signal).c_str(), static_cast<unsigned long long>(s.done),
                 static_cast<unsigned long long>(scene.steps));
    return 128 + signal;
  }
  return 0;
}

template <class T>
int run_typed(const Scene& scene, const RunOptions& o, const RunContext& context) {
  const StepperOptions options = stepper_options(o);
  World<T> world = build_world<T>(scene, o, options);
  // Opened once the world stands (a scene that fails leaves no file behind), before the run.
  ReportFile summary_file(o.summary_path, "summary");
  const StepPlan plan = plan_steps(scene, o, options);
  std::optional<TrajectoryWriter> trajectory;
  if (!o.trajectory_path.empty()) trajectory.emplace(o.trajectory_path, world.rigid.size() > 0);
  const double initial_energy = world.total_energy();
  const Stepped stepped = step_scene(world, scene, o, options, plan.tolerances, trajectory);
  const nlohmann::ordered_json summary = summarize(world, scene, o, plan, stepped, initial_energy, context);
  summary_file.write(summary);
  if (!o.quiet) print_summary(summary);
  return finish(summary, scene, stepped);
}

}  // namespace

int run_scene(const RunOptions& o) {
  Scene scene = scene_with_overrides(o);
  std::optional<nlohmann::ordered_json> choice;
  if (scene.method == "auto") {
    const auto start = Clock::now();
    const MethodChoice c = [&] {
      try {
        return choose_method(scene, *scene.tolerance);
      } catch (const Error& e) {
        throw Error(o.scene_path + ": " + e.what());
      }
    }();
    choice = nlohmann::ordered_json{{"method", std::string(c.method->name)}};
    if (c.step_tolerance) {
      (*choice)["rtol"] = *c.step_tolerance;  // the duration stays dt x steps
      scene.rtol = scene.atol = *c.step_tolerance;
    } else {
      choice->update({{"dt", c.dt}, {"steps", c.steps}});
      scene.dt = c.dt;
      scene.steps = c.steps;
    }
    choice->update({{"precision", std::string(precision_name(c.precision))},
                    {"force_evaluations", c.evaluations},
                    {"tolerance", *scene.tolerance}, {"estimated_error", c.estimated_error},
                    {"seconds", std::chrono::duration<double>(Clock::now() - start).count()},
                    {"reason", c.reason}});
    scene.method = std::string(c.method->name);
    scene.precision = c.precision;
  }
  const RunContext context{choice};
  return with_precision(scene.precision, [&]<class T>() { return run_typed<T>(scene, o, context); });
}

}  // namespace kinema::cli
