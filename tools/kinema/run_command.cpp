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

template <class T>
int run_typed(const Scene& scene, const RunOptions& o, const RunContext& context) {
  StepperOptions options;
  options.isa = o.isa;
  // More threads than the machine has would only wait on each other (and make oneTBB warn).
  options.threads = std::min(o.threads == 0 ? hardware_threads() : o.threads, hardware_threads());
  options.relaxed_fma = o.relaxed_fma;
  World<T> world = [&] {
    try {
      return World<T>(scene, method_by_name(scene.method), options);
    } catch (const Error& e) {  // bodies or forces the precision cannot hold: name the file
      throw Error(o.scene_path + ": " + e.what());
    }
  }();
  // Opened once the world stands (a scene that fails leaves no file behind), before the run.
  ReportFile summary_file(o.summary_path, "summary");
  const StiffnessEstimate stiffness = stiffness_at_start(scene, options);
  const double stable_step = largest_stable_step(method_by_name(scene.method), stiffness);
  std::optional<Tolerances> tolerances = tolerances_of(scene);
  if (tolerances && stable_step > 0) tolerances->max_step = stable_step;  // error control never goes past it
  if (!tolerances) check_stable_step(scene, o, stiffness, stable_step);
  std::optional<TrajectoryWriter> trajectory;
  if (!o.trajectory_path.empty()) trajectory.emplace(o.trajectory_path, world.rigid.size() > 0);
  const T h = T(scene.dt);
  const double initial_energy = world.total_energy();
  const std::size_t bodies = world.particles.size() + world.rigid.size();

  // In chunks, for the progress bar, the trajectory and signals: the same bits as one call.
  // Error-controlled steps land on each chunk's end, so their chunks are longer: a sixteenth
  // of the run or more.
  const std::uint64_t per_chunk = std::uint64_t(std::max(1.0, kBodyStepsPerChunk / double(std::max<std::size_t>(bodies, 1))));
  const std::uint64_t chunk = tolerances ? std::max<std::uint64_t>({1, scene.steps / 16, per_chunk})
                                         : std::min<std::uint64_t>(std::max<std::uint64_t>(1, scene.steps / 100), per_chunk);
  double wall_seconds = 0;  // stepping only: loading, checking and writing are not timed
  Progress progress("kinema run", o.quiet);
  std::uint64_t done = 0;
  if (trajectory) trajectory->write(0, world.time(), world.particles, world.rigid);
  std::optional<BlowUp> blow_up;
  AdaptiveStats adaptive;
  while (done < scene.steps && interrupting_signal() == 0) {
    std::uint64_t n = std::min(chunk, scene.steps - done);
    if (trajectory) n = std::min(n, o.every - done % o.every);  // stop at each K-th step
    const auto start = Clock::now();
    if (tolerances) {
      advance_adaptive(world, double(done + n) * scene.dt, *tolerances, adaptive);
    } else {
      world.advance(h, n);
    }
    wall_seconds += std::chrono::duration<double>(Clock::now() - start).count();
    const bool finite = world.finite();
    if (!finite) blow_up = find_blow_up<T>(scene, options, world, done, n);
    done += n;
    progress.update(double(done) / double(scene.steps));
    if (trajectory && (done % o.every == 0 || done == scene.steps || !finite)) {
      trajectory->write(done, world.time(), world.particles, world.rigid);
    }
    if (!finite) break;
  }
  if (trajectory) trajectory->close();
  progress.finish();

  const Stepper<T>& stepper = world.main_stepper();
  nlohmann::ordered_json summary;
  summary["scene"] = scene.name;
  summary["bodies"] = bodies;
  summary["particles"] = world.particles.size();
  summary["rigid_bodies"] = world.rigid.size();
  summary["steps"] = done;
  summary["method"] = std::string(stepper.method().name);
  summary["path"] = stepper.fused() ? "fused" : "staged";
  summary["dt"] = scene.dt;
  summary["t_final"] = world.time();
  summary["precision"] = std::string(precision_name(scene.precision));
  summary["isa"] = std::string(isa_name(stepper.isa()));
  summary["relaxed_fma"] = o.relaxed_fma;
  summary["threads"] = stepper.threads();
  summary["workers_used"] = stepper.chosen_workers();  // what the measurements favoured (0: the calling thread)
  if (tolerances) {
    summary["rtol"] = tolerances->rtol;
    summary["atol"] = tolerances->atol;
    summary["accepted_steps"] = adaptive.accepted;
    summary["rejected_steps"] = adaptive.rejected;
    summary["smallest_step"] = adaptive.smallest_step;
    summary["largest_step"] = adaptive.largest_step;
  }
  summary["stiffness"] = stiffness.magnitude;
  if (std::isfinite(stable_step)) summary["largest_stable_step"] = stable_step;
  summary["force_evaluations"] = tolerances ? adaptive.evaluations
                                            : done * std::uint64_t(stepper.method().evaluations());
  summary["wall_seconds"] = wall_seconds;
  summary["body_steps_per_second"] = wall_seconds > 0 ? double(bodies) * double(done) / wall_seconds : 0.0;
  summary["energy_initial"] = initial_energy;
  summary["energy_final"] = world.total_energy();
  summary["finite"] = !blow_up;
  if (blow_up) {
    auto& where = summary["first_non_finite"];
    if (blow_up->first == blow_up->last) {
      where["step"] = blow_up->last;
    } else {
      where["between_steps"] = {blow_up->first, blow_up->last};
    }
    where.update({{"t", blow_up->t}, {"body", blow_up->body}, {"field", blow_up->field}});
  }
  const int signal = interrupting_signal();
  if (signal != 0 && done < scene.steps) {
    summary["interrupted"] = signal_name(signal);
    summary["steps_requested"] = scene.steps;
  }
  if (context.auto_choice) summary["auto"] = *context.auto_choice;

  summary_file.write(summary);
  if (!o.quiet) print_summary(summary);
  if (blow_up) {
    const std::string steps = blow_up->first == blow_up->last
        ? "after step " + std::to_string(blow_up->last)
        : "between steps " + std::to_string(blow_up->first) + " and " + std::to_string(blow_up->last);
    std::fprintf(stderr,
                 "kinema: error: the state is no longer finite %s (t = %g): body %zu, %s (try a "
                 "smaller dt or a more stable method)\n",
                 steps.c_str(), blow_up->t, blow_up->body, blow_up->field.c_str());
    return 3;
  }
  if (summary.contains("interrupted")) {
    std::fprintf(stderr, "kinema: stopped by %s after step %llu of %llu; outputs are complete to there\n",
                 signal_name(signal).c_str(), static_cast<unsigned long long>(done),
                 static_cast<unsigned long long>(scene.steps));
    return 128 + signal;
  }
  return 0;
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
