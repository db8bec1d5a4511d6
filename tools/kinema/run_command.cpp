#include "run_command.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <sys/stat.h>
#include <variant>

#include <nlohmann/json.hpp>

#include "auto_choice.hpp"
#include "interrupt.hpp"
#include "kinema/files.hpp"
#include "kinema/scenes.hpp"
#include "kinema/stability.hpp"
#include "numbers.hpp"
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

// Options that would do nothing with the run's method are refused, not ignored.
void check_method_options(const RunOptions& o, const std::string& method) {
  const bool solves_set = o.implicit_tolerance || o.implicit_iterations || o.implicit_preconditioner;
  if (method == "auto") {
    // auto's pilots measure each candidate with its default solves: a looser solve would
    // break the tolerance the choice was made for.
    if (solves_set) {
      throw Error("--implicit-tolerance, --implicit-iterations and --implicit-preconditioner set the linear solves of "
                  "a named implicit method; --method auto chooses with the default solves");
    }
    return;
  }
  if (o.tolerance) throw Error("--tolerance bounds the error of --method auto's choice; the method here is " + method);
  const bool implicit = method_by_name(method).kind == MethodKind::linearly_implicit;
  if (!implicit && solves_set) {
    throw Error("--implicit-tolerance, --implicit-iterations and --implicit-preconditioner set the linear solves of "
                "implicit_euler and ros2; the method here is " + method);
  }
}

// --relaxed-fma changes the scalar and SSE2 kernels only: with an instruction set that has
// FMA units it would do nothing. Named by --isa: refused; chosen on this CPU: a note.
void check_relaxed_fma(const RunOptions& o) {
  if (!o.relaxed_fma) return;
  const Isa isa = o.isa == Isa::automatic ? best_isa() : o.isa;
  if (isa != Isa::avx2 && isa != Isa::avx512) return;
  const std::string name(isa_name(isa));
  if (o.isa != Isa::automatic) {
    throw Error("--relaxed-fma changes the scalar and SSE2 kernels; --isa " + name + " always uses its FMA units");
  }
  if (!o.quiet) {
    std::fprintf(stderr, "kinema: note: --relaxed-fma changes the scalar and SSE2 kernels; this CPU runs %s, which "
                 "always uses its FMA units (--isa sse2 to relax)\n", name.c_str());
  }
}

// A scene's "tolerance" bounds method auto's choice. With another method named in the scene
// it would do nothing: refused, as --tolerance is. With another method from --method (a run
// of an auto scene at a chosen method) it is kept for auto runs of the scene: a note says so.
void check_scene_tolerance(const RunOptions& o, const Scene& scene) {
  if (!scene.tolerance || scene.method == "auto") return;
  if (!o.method) {
    throw Error("tolerance: bounds the error of method auto's choice; the scene's method is " + scene.method);
  }
  if (!o.quiet) {
    std::fprintf(stderr, "kinema: note: the scene's tolerance bounds method auto's choice; unused with --method %s\n",
                 scene.method.c_str());
  }
}

}  // namespace

// Whether a trajectory path is a file of its own in a folder, or none yet: not a device, a
// pipe, or the file a standard stream is on (written through the stream).
bool trajectory_is_own_file(const std::string& path) {
  struct stat st{};
  return ::stat(path.c_str(), &st) != 0 || (S_ISREG(st.st_mode) && standard_stream_at(path) < 0);
}

// A run that keeps checkpoints syncs its trajectory with them and a resumed run continues
// it from the length it had: a device or a pipe can do neither (refused before any work).
void check_trajectory_resumable(const RunOptions& o) {
  if (o.checkpoint.path.empty() || o.trajectory_path.empty() || trajectory_is_own_file(o.trajectory_path)) return;
  throw Error("--out " + printable(o.trajectory_path) +
              ": with --checkpoint the trajectory is a file that a resumed run continues, not a device, a pipe or a "
              "standard stream");
}

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
  check_method_options(o, scene.method);
  check_relaxed_fma(o);
  check_dt_option(o.dt, scene.precision);
  naming_scene(o.scene_path, [&] {
    if (!std::isfinite(scene.dt * double(scene.steps))) {
      char text[160];
      std::snprintf(text, sizeof text, "dt x steps (%llu steps of %g s) overflows the clock",
                    static_cast<unsigned long long>(scene.steps), scene.dt);
      throw Error(text);
    }
    if (scene.method == "auto" && !scene.tolerance) {
      throw Error("method auto needs a tolerance (the scene's \"tolerance\" or --tolerance)");
    }
    check_scene_tolerance(o, scene);
    if ((scene.rtol || scene.atol) && (scene.method == "auto" || method_by_name(scene.method).embedded_order == 0)) {
      throw Error("rtol and atol control the steps of a method with an embedded pair (bs3, dopri5), not " +
                  scene.method);
    }
    if ((scene.rtol || scene.atol) && (!scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid))) {
      // The library's rigid error control polls no stop request: a run could not be
      // interrupted or checkpointed inside it.
      throw Error("rtol and atol control the steps of particles here (rigid bodies: Stepper::advance_to in the "
                  "library); the scene has rigid bodies");
    }
    with_precision(scene.precision, [&]<class T>() { check_scene<T>(scene); });
  });
  return scene;
}

namespace {

// The summary for people: a line per field with its unit, auto's choice as its line.
void print_summary(const nlohmann::ordered_json& summary) {
  std::printf("kinema run: %s\n", printable(summary["scene"].get<std::string>()).c_str());
  const nlohmann::ordered_json& units = summary["units"];
  for (const auto& [key, value] : summary.items()) {
    if (key == "scene" || key == "units") continue;
    const nlohmann::ordered_json& shown = key == "auto" ? value["choice"] : value;
    std::string text = shown.is_string() ? shown.get<std::string>() : shown.dump();
    if (units.contains(key) && !shown.is_null()) text.append(" ").append(units[key].get<std::string>());
    std::printf("  %-22s %s\n", key.c_str(), printable(text).c_str());
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

void add_stats(AdaptiveStats& total, const AdaptiveStats& s) {
  total.smallest_step = total.accepted == 0 ? s.smallest_step
                        : s.accepted == 0   ? total.smallest_step
                                            : std::min(total.smallest_step, s.smallest_step);
  total.largest_step = std::max(total.largest_step, s.largest_step);
  total.accepted += s.accepted, total.rejected += s.rejected, total.evaluations += s.evaluations;
  if (s.next_step > 0) total.next_step = s.next_step;
}

// Error-controlled steps to t, starting from the size the last call proposed; each call's
// event hits to `record`. A signal or a checkpoint due stops the call between steps; for a
// checkpoint it goes on after (the bits of one call). Returns false when a signal or a stop
// event stopped it short of t (the stepper keeps the rest).
template <class T>
bool advance_adaptive(World<T>& world, double t, Tolerances tolerances, AdaptiveStats& total,
                      CheckpointTimer& checkpoints, const std::function<void()>& save,
                      const std::function<void()>& record) {
  tolerances.initial_step = total.next_step;
  // A checkpoint waits for the step under way (stopping inside would lose it, and an attempt
  // longer than the interval would never finish); a signal does not.
  const StopRequest checkpoint_due = [&] { return checkpoints.due(); };
  for (;;) {
    const AdaptiveStats s = world.advance_to(t, tolerances, checkpoint_due, interrupt_request());
    add_stats(total, s);
    record();
    if (world.stopped_at_event()) return false;
    if (!s.stopped) return true;
    if (interrupting_signal() != 0) return false;
    save();
  }
}

// The stiffness of the scene at its start, in double whatever the run's precision (finite
// differences in float lose half their digits): on the particles, else the rigid bodies
// (their rotation too); on 1024 of them spread evenly when only local terms act (each body
// is then a system of its own, and the stiffest of a sample stands for the rest).
// 40 Jacobian products (57 force evaluations) on the run's threads: a few tenths of a second
// for the 4096-body cluster.
// An implicit method takes the springs implicitly: what can break it is the rest, so the
// estimate leaves the springs out (their bodies stay).
StiffnessEstimate stiffness_at_start(const Scene& full, const StepperOptions& options) {
  Scene scene = full;
  if (method_by_name(scene.method).kind == MethodKind::linearly_implicit) scene.springs.clear();
  const ForceModel<double> forces = make_forces<double>(scene);
  const bool sampled = forces.fusable() && !forces.couples_rigid();
  const Scene source = sampled ? sample_bodies(scene, 1024) : scene;
  const ParticleSet<double> bodies = make_particles<double>(source);
  if (bodies.size() > 0) return estimate_stiffness(bodies, forces, 0, 40, options, interrupt_request());
  return estimate_stiffness(make_rigid_bodies<double>(source), forces, 0, 40, options, interrupt_request());
}

std::string mode_name(const StiffnessEstimate& e) {
  return e.angle < 0.3 ? "damping" : e.angle > 1.27 ? "oscillation" : "damped oscillation";
}

// Warns (or with --strict refuses) when dt is past the method's largest stable step and the
// fastest mode grows more than twofold over the run (a weak instability, such as midpoint's
// on an oscillation, that a run never shows is left alone).
void check_stable_step(const Scene& scene, const RunOptions& o, const StiffnessEstimate& e, double stable) {
  if (!(scene.dt > stable)) return;
  const Method& method = method_by_name(scene.method);
  const double log_growth =
      double(scene.steps) * std::log(growth_per_step(method, e, scene.dt, ImplicitMode::explicit_forces));
  if (!(log_growth > std::log(2.0))) return;
  // Springs are what the implicit methods take implicitly: name them where they would hold
  // (and the scene would take them).
  const bool springs = takes_implicit_methods(scene) && method_by_name(scene.method).kind != MethodKind::linearly_implicit;
  char growth[48];
  if (log_growth < std::log(1e300)) {
    std::snprintf(growth, sizeof growth, "%.3g-fold", std::exp(log_growth));
  } else {
    std::snprintf(growth, sizeof growth, "more than 1e300-fold");  // past what double holds
  }
  char text[500];
  std::snprintf(text, sizeof text,
                "dt %g is past the largest stable step of %s on this scene, %.3g: its fastest mode (%s at "
                "|lambda| = %.4g /s) grows %s over the run%s",
                scene.dt, scene.method.c_str(), stable, mode_name(e).c_str(), e.magnitude, growth,
                springs ? " (an implicit method holds at this step where the springs are the stiff part: "
                          "--method implicit_euler or ros2)"
                        : "");
  if (o.strict) throw Error(o.scene_path + ": " + text + " (--strict)");
  // Not silenced by --quiet: it says the result may be worthless.
  std::fprintf(stderr, "kinema: warning: %s\n", printable(text).c_str());
}

// What happened before stepping that the summary reports.
struct RunContext {
  std::optional<nlohmann::ordered_json> auto_choice;  // AutoChoice::record
};

StepperOptions stepper_options(const RunOptions& o) {
  StepperOptions options;
  options.isa = o.isa;
  // More threads than the machine has would only wait on each other (and make oneTBB warn).
  options.threads = std::min(o.threads == 0 ? hardware_threads() : o.threads, hardware_threads());
  options.relaxed_fma = o.relaxed_fma;
  options.implicit_tolerance = o.implicit_tolerance.value_or(options.implicit_tolerance);
  options.implicit_max_iterations = o.implicit_iterations.value_or(options.implicit_max_iterations);
  const std::string preconditioner = o.implicit_preconditioner.value_or("automatic");
  options.implicit_preconditioner = preconditioner == "jacobi"      ? ImplicitPreconditioner::jacobi
                                    : preconditioner == "multigrid" ? ImplicitPreconditioner::multigrid
                                                                    : ImplicitPreconditioner::automatic;
  return options;
}

// Bodies or forces the precision cannot hold are the scene file's fault.
template <class T>
World<T> build_world(const Scene& scene, const RunOptions& o, const StepperOptions& options) {
  return naming_scene(o.scene_path, [&] { return World<T>(scene, method_by_name(scene.method), options); });
}

template <class T>
std::size_t body_count(const World<T>& world) {
  return world.particles.size() + world.rigid.size();
}

// What the run knows about its steps before the first: the scene's stiffness at the start,
// the method's largest stable step there, and the error control if any.
struct StepPlan {
  bool estimated = false;  // true once the estimate ran (false: it would have cost more than the run)
  StiffnessEstimate stiffness;
  double stable_step = 0;
  std::optional<Tolerances> tolerances;
};

// The estimate costs 57 evaluations in double and 40 x 20 dot products of 6 numbers per
// body: on a short run of a large coupled scene, more than the run. It is then left out
// (with --strict it is always made: the run must be shown stable).
bool estimate_pays(const Scene& scene, const RunOptions& o, double bodies) {
  constexpr double kAlwaysWorth = double(1 << 26);
  const bool local = !scene.nbody && scene.springs.empty() && scene.body_springs.springs.empty();
  if (o.strict || local) return true;  // local terms: 1024 bodies at most
  const double estimate = 57 * evaluation_cost(scene) + 800 * bodies;
  const double run = double(scene.steps) * method_by_name(scene.method).evaluations() * evaluation_cost(scene);
  return estimate <= std::max(run, kAlwaysWorth);
}

StepPlan plan_steps(const Scene& scene, const RunOptions& o, const StepperOptions& options, double bodies) {
  StepPlan plan;
  const bool pays = estimate_pays(scene, o, bodies);
  if (!pays && !o.quiet) {
    std::fprintf(stderr, "kinema: note: the stiffness estimate would cost more than the run's %llu steps; "
                 "left out, so dt is not checked against the stable step (--strict makes it)\n",
                 static_cast<unsigned long long>(scene.steps));
  }
  if (pays) plan.stiffness = stiffness_at_start(scene, options), plan.estimated = true;
  // An estimate that overflowed bounds nothing (check_plan says so): no stable step, no cap.
  const bool bounded = plan.estimated && std::isfinite(plan.stiffness.magnitude);
  // An implicit method's estimate is of the forces it steps explicitly (stiffness_at_start).
  plan.stable_step = bounded ? largest_stable_step(method_by_name(scene.method), plan.stiffness,
                                                   ImplicitMode::explicit_forces)
                             : std::numeric_limits<double>::infinity();
  plan.tolerances = tolerances_of(scene);
  // Error control never goes past the stable step; fixed steps are checked against it
  // (check_plan, once the plan is kept: a refusal's summary reports the estimate).
  if (plan.tolerances && plan.stable_step > 0) plan.tolerances->max_step = plan.stable_step;
  return plan;
}

// Warns (or with --strict refuses) when dt is past the stable step, or when the stiffness
// estimate itself overflowed double (forces too large near the start): then nothing checks dt.
void check_plan(const Scene& scene, const RunOptions& o, const StepPlan& plan) {
  if (plan.estimated && !std::isfinite(plan.stiffness.magnitude)) {
    const std::string text = "the stiffness estimate overflows double on this scene (forces too large near its "
                             "start): dt is not checked against the largest stable step";
    if (o.strict) throw Error(o.scene_path + ": " + text + " (--strict)");
    std::fprintf(stderr, "kinema: warning: %s\n", text.c_str());
    return;
  }
  if (!plan.tolerances) check_stable_step(scene, o, plan.stiffness, plan.stable_step);
}

// Steps per advance call: for the progress bar, the trajectory and signals (the same bits as
// one call). Error-controlled steps land on each call's end, so their calls are longer: a
// sixteenth of the run or more.
// Fixed steps are bounded by what a step costs: a body-step, and under N-body gravity each force
// evaluation's N^2 interactions too, an interaction about half a body-step (so a chunk stays
// near 50 ms of stepping, and a signal is answered that soon, at 4096 bodies as at 4). Error
// control keeps its bound in body-steps: its calls' ends change its steps, and it answers
// signals between its own steps anyway.
std::uint64_t steps_per_call(const Scene& scene, std::size_t bodies, bool adaptive) {
  const double n = double(std::max<std::size_t>(bodies, 1));
  const auto bounded = [](double cost) { return std::uint64_t(std::max(1.0, kBodyStepsPerChunk / cost)); };
  if (adaptive) return std::max<std::uint64_t>({1, scene.steps / 16, bounded(n)});
  const double evaluations = method_by_name(scene.method).evaluations();  // auto has chosen by now
  const double cost = n + (scene.nbody ? evaluations * n * n / 2 : 0);
  return std::min<std::uint64_t>(std::max<std::uint64_t>(1, scene.steps / 100), bounded(cost));
}

// What stepping did.
struct Stepped {
  std::uint64_t done = 0;   // steps of dt completed (error control: their span)
  std::uint64_t calls = 0;  // advance or advance_to calls
  double wall_seconds = 0;  // stepping only: loading, checking and writing are not timed
  std::optional<BlowUp> blow_up;
  AdaptiveStats adaptive;
  std::optional<std::uint64_t> resumed_at;  // the step a checkpoint resumed the run from
  std::uint64_t checkpoints = 0;            // written by this process
  std::optional<std::string> error;         // what ended the run early
  std::string fingerprint;                  // of the scene and options, with checkpoints
  std::optional<double> final_energy;       // none when a signal came while it was summed
  std::string event_rows;                   // events.csv, past its header
  std::uint64_t events = 0;
  std::optional<std::string> stop_event;    // the event that ended the run
};

const char* event_type(const EventSpec& e) {
  return std::holds_alternative<PlaneEvent>(e.kind) ? "plane" : std::holds_alternative<DistanceEvent>(e.kind) ? "distance" : "speed";
}

// The hits of the last advance call as rows of events.csv.
template <class T>
void record_events(const World<T>& world, const Scene& scene, Stepped& s) {
  for (const EventHit<T>& hit : world.event_hits()) {
    char text[80];
    std::snprintf(text, sizeof text, "%.17g,%zu,%d,%s", hit.time, hit.body, hit.event,
                  event_type(scene.events[std::size_t(hit.event)]));
    s.event_rows += text;
    for (const auto& state : {hit.position, hit.velocity}) {
      for (int d = 0; d < 3; ++d) {
        std::snprintf(text, sizeof text, kRoundTripColumn<T>, double(state[d]));
        s.event_rows += text;
      }
    }
    s.event_rows += '\n';
    ++s.events;
  }
  if (!world.stopped_at_event()) return;
  for (const EventHit<T>& hit : world.event_hits()) {  // the first stop hit in time, then body, order
    const EventSpec& spec = scene.events[std::size_t(hit.event)];
    if (spec.action != EventAction::stop) continue;
    s.stop_event = "events[" + std::to_string(hit.event) + "] (" + event_type(spec) + "), body " + std::to_string(hit.body);
    return;
  }
}

std::filesystem::path events_path(const RunOptions& o) {
  return std::filesystem::path(o.trajectory_path).parent_path() / "events.csv";
}

// events.csv beside the trajectory: every hit of the run (of a resumed run: since the resume).
void write_events(const RunOptions& o, const Scene& scene, const Stepped& s) {
  if (scene.events.empty() || o.trajectory_path.empty()) return;
  const std::string text = "time,body,event,type,px,py,pz,vx,vy,vz\n" + s.event_rows;
  write_whole_file(events_path(o), std::as_bytes(std::span(text.data(), text.size())), "events");
}

// Events are watched on a model of local terms; events.csv is a file of its own.
void check_events(const Scene& scene, const RunOptions& o) {
  if (scene.events.empty()) return;
  if (scene.nbody || !scene.springs.empty()) {
    throw Error(o.scene_path + ": events are watched with local terms only: a scene with nbody or springs cannot have them");
  }
  if (!o.trajectory_path.empty() && !trajectory_is_own_file(o.trajectory_path)) {
    // Beside /dev/null it would be /dev/events.csv.
    throw Error(o.scene_path + ": its events go to events.csv beside the trajectory, and --out " +
                printable(o.trajectory_path) + " is no file in a folder (a device, a pipe or a standard stream)");
  }
  if (!o.trajectory_path.empty()) {
    check_apart(o.scene_path + ": its events go to", events_path(o).string(),
                {{"the scene is read from", o.scene_path}, {"--out names", o.trajectory_path},
                 {"--summary names", o.summary_path}, {"--checkpoint names", o.checkpoint.path},
                 {"--resume names", o.checkpoint.resume_path}});
  }
}

// A span a signal cut short is not searched for the step that stopped being finite: the
// steps it completed are the range reported.
template <class T>
void note_non_finite(const World<T>& world, std::uint64_t from, Stepped& s) {
  if (s.done == from) return;
  if (auto bad = first_non_finite(world)) s.blow_up = BlowUp{from + 1, s.done, world.time(), bad->body, bad->field};
}

// The energy at the end; none when a signal comes while it is summed (N-body gravity's
// potential at 32768 bodies takes seconds).
template <class T>
std::optional<double> final_energy(const World<T>& world) {
  try {
    return world.total_energy(interrupt_request());
  } catch (const Stopped&) {
    return std::nullopt;
  }
}

// The implicit solves' options, as the stepper takes them, under an implicit method only
// (the other methods' fingerprints stay as they were).
std::string implicit_fingerprint(const RunOptions& o, const Scene& scene) {
  if (scene.method == "auto" || method_by_name(scene.method).kind != MethodKind::linearly_implicit) return "";
  const StepperOptions options = stepper_options(o);
  const double given = options.implicit_tolerance, tolerance = given > 0 ? given
                       : scene.precision == Precision::single ? kDefaultImplicitTolerance<float>
                                                              : kDefaultImplicitTolerance<double>;
  char text[140];
  // The preconditioner the solves take, named only where it is not the default's choice:
  // the fingerprints of runs that keep the default stay as they were.
  std::size_t network = 0;
  for (const Springs& springs : scene.springs) network = std::max(network, network_reach(springs.pairs));
  const bool multigrid = takes_multigrid(options.implicit_preconditioner, network);
  const std::string preconditioner = multigrid == takes_multigrid(ImplicitPreconditioner::automatic, network)
                                         ? ""
                                         : multigrid ? " implicit_preconditioner=multigrid" : " implicit_preconditioner=jacobi";
  std::snprintf(text, sizeof text, " implicit_tolerance=%a implicit_iterations=%d%s", tolerance,
                options.implicit_max_iterations, preconditioner.c_str());
  return text;
}

// What the run's results depend on beyond the bodies: the scene file and the options that
// change them (not --threads or --isa: every count and instruction set gives the same bits).
std::string run_fingerprint(const RunOptions& o, const Scene& scene) {
  char text[500];
  std::snprintf(text, sizeof text, "method=%s dt=%a steps=%llu precision=%d rtol=%a atol=%a tolerance=%a every=%llu "
                "trajectory=%d relaxed=%d%s", scene.method.c_str(), scene.dt, static_cast<unsigned long long>(scene.steps),
                int(scene.precision), scene.rtol.value_or(-1), scene.atol.value_or(-1), scene.tolerance.value_or(-1),
                static_cast<unsigned long long>(o.every), int(!o.trajectory_path.empty()), int(o.relaxed_fma),
                implicit_fingerprint(o, scene).c_str());
  return fingerprint_of(o.scene_path, text);
}

// The run's record in a checkpoint: its progress and what it measured so far.
RunRecord run_record(const Stepped& s, double initial_energy,
                     std::optional<std::uint64_t> trajectory_bytes) {
  const AdaptiveStats& a = s.adaptive;
  nlohmann::json f = {{"done", s.done}, {"calls", s.calls}, {"wall_seconds", exact(s.wall_seconds)},
                      {"accepted", a.accepted}, {"rejected", a.rejected}, {"evaluations", a.evaluations},
                      {"smallest_step", exact(a.smallest_step)}, {"largest_step", exact(a.largest_step)},
                      {"next_step", exact(a.next_step)}, {"initial_energy", exact(initial_energy)}};
  if (trajectory_bytes) f["trajectory_bytes"] = *trajectory_bytes;
  if (s.stop_event) f["stopped_by_event"] = *s.stop_event;  // the run is over: a resume steps no more
  return {"run", s.fingerprint, f};
}

// How far a checkpoint's run got, as the run goes on from it.
struct Resumed {
  Stepped stepped;
  double initial_energy = 0;
  std::optional<std::uint64_t> trajectory_bytes;
};

Resumed resumed_from(const nlohmann::json& f) {
  Resumed r;
  Stepped& s = r.stepped;
  s.done = f.at("done"), s.calls = f.at("calls"), s.wall_seconds = exact(f.at("wall_seconds").get<std::uint64_t>());
  AdaptiveStats& a = s.adaptive;
  a.accepted = f.at("accepted"), a.rejected = f.at("rejected"), a.evaluations = f.at("evaluations");
  a.smallest_step = exact(f.at("smallest_step").get<std::uint64_t>());
  a.largest_step = exact(f.at("largest_step").get<std::uint64_t>());
  a.next_step = exact(f.at("next_step").get<std::uint64_t>());
  r.initial_energy = exact(f.at("initial_energy").get<std::uint64_t>());
  if (f.contains("trajectory_bytes")) r.trajectory_bytes = f.at("trajectory_bytes").get<std::uint64_t>();
  if (f.contains("stopped_by_event")) s.stop_event = f.at("stopped_by_event").get<std::string>();
  s.resumed_at = s.done;
  return r;
}

// The world as the checkpoint left it, and the run's progress then.
template <class T>
Resumed resume(World<T>& world, const Scene& scene, const RunOptions& o, const std::string& fingerprint) {
  const std::string& path = o.checkpoint.resume_path;
  const CheckpointReader in = CheckpointReader::load(path);
  const RunRecord record = decode(in.user_data(), "run", fingerprint, path);
  try {
    world.restore(in);
    Resumed r = resumed_from(record.fields);
    if (r.stepped.done > scene.steps) throw Error("it is past the run's last step");
    return r;
  } catch (const nlohmann::json::exception&) {
    throw Error(printable(path) + ": its run record is incomplete");
  } catch (const Error& e) {
    throw Error(printable(path) + ": " + e.what());
  }
}

// Steps from `done` to done + n (error control: over that span), timed.
// Returns false when a signal stopped it short of the span's end: fixed steps add the steps
// they completed to `done` (one N-body step can take seconds: a signal ends it inside). Only stepping is
// timed: the clock pauses while a checkpoint is written, and what ran before it is counted in
// it. A span a signal cut short is no call done (a resume makes it again).
template <class T>
bool advance_timed(World<T>& world, const Scene& scene, const std::optional<Tolerances>& tolerances,
                   std::uint64_t n, Stepped& s, CheckpointTimer& checkpoints, const std::function<void()>& save) {
  auto segment = Clock::now();
  const auto seconds_since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
  const auto timed_save = [&] {
    s.wall_seconds += seconds_since(segment);
    save();
    segment = Clock::now();
  };
  bool whole = true;
  if (tolerances) {
    const double start = world.time();
    whole = advance_adaptive(world, double(s.done + n) * scene.dt, *tolerances, s.adaptive, checkpoints, timed_save,
                             [&] { record_events(world, scene, s); });
    // A stop event: the steps of dt begun, the last one cut at the event.
    if (s.stop_event) s.done += std::uint64_t(std::ceil((world.time() - start) / scene.dt - 1e-9));
  } else {
    const std::uint64_t taken = world.advance(T(scene.dt), n, interrupt_request());
    record_events(world, scene, s);
    if (taken < n || s.stop_event) s.done += taken, whole = false;
  }
  s.wall_seconds += seconds_since(segment);
  if (whole) ++s.calls;
  return whole;
}

// Every K-th step, the last, and the one that stopped being finite.
bool trajectory_due(const Scene& scene, const RunOptions& o, std::uint64_t done, bool finite) {
  return done % o.every == 0 || done == scene.steps || !finite;
}

// Writes the world's checkpoint with the run's record, the trajectory synced first so that the
// length it records is on disk.
template <class T>
void save_checkpoint(const World<T>& world, const RunOptions& o, Stepped& s, double initial_energy,
                     std::optional<TrajectoryWriter>& trajectory) {
  std::optional<std::uint64_t> length;
  if (trajectory) length = trajectory->sync();
  CheckpointWriter out;
  world.save(out);
  out.set_user_data(encode(run_record(s, initial_energy, length)));
  out.save(o.checkpoint.path);
  ++s.checkpoints;
}

template <class T>
void step_scene(World<T>& world, const Scene& scene, const RunOptions& o, const StepperOptions& options,
                const std::optional<Tolerances>& tolerances, std::optional<TrajectoryWriter>& trajectory,
                double initial_energy, Stepped& s) {
  const std::uint64_t chunk = steps_per_call(scene, body_count(world), tolerances.has_value());
  Progress progress("kinema run", o.quiet);
  CheckpointTimer checkpoints(o.checkpoint);
  if (trajectory && !s.resumed_at) trajectory->write(0, world.time(), world.particles, world.rigid);
  while (s.done < scene.steps && !s.stop_event && interrupting_signal() == 0) {
    std::uint64_t n = std::min(chunk, scene.steps - s.done);
    if (trajectory) n = std::min(n, o.every - s.done % o.every);  // stop at each K-th step
    const auto save = [&] { save_checkpoint(world, o, s, initial_energy, trajectory), checkpoints.saved(); };
    // Short of the span's end only on a signal: the checkpoint below keeps the rest to do.
    const std::uint64_t from = s.done;
    if (!advance_timed(world, scene, tolerances, n, s, checkpoints, save)) {
      if (s.stop_event && trajectory) trajectory->write(s.done, world.time(), world.particles, world.rigid);
      if (!s.stop_event) note_non_finite(world, from, s);
      break;
    }
    const bool finite = world.finite();
    if (!finite) s.blow_up = find_blow_up<T>(scene, options, world, s.done, n);
    s.done += n;
    progress.update(double(s.done) / double(scene.steps));
    if (trajectory && trajectory_due(scene, o, s.done, finite)) {
      trajectory->write(s.done, world.time(), world.particles, world.rigid);
    }
    if (!finite) break;  // the last checkpoint stays the last finite state
    if (checkpoints.due()) save();
  }
  // The end, or where a signal stopped it: what a resume goes on from.
  if (checkpoints.enabled() && !s.blow_up) save_checkpoint(world, o, s, initial_energy, trajectory);
  if (trajectory) trajectory->close();
  write_events(o, scene, s);
  progress.finish();
}

// The steps the state took: under error control the accepted ones, else every step of dt.
std::uint64_t steps_taken(const StepPlan& plan, const Stepped& s) {
  return plan.tolerances ? s.adaptive.accepted : s.done;
}

// Why the stepper used the workers it did. It times its calls with each worker count and
// keeps the fastest for that kind and size of call; N-body passes take every worker.
std::string workers_note(unsigned threads, unsigned used, const StepPlan& plan, const Stepped& s, bool nbody) {
  if (threads <= 1) return "a job system of one worker takes every call";
  std::string note = used == 0
      ? "timed: the calling thread alone was as fast as " + std::to_string(threads) + " workers or faster"
      : "timed: " + std::to_string(used) + " of " + std::to_string(threads) + " workers were fastest";
  note += " for calls of this kind and size";
  if (!plan.tolerances && s.calls > 0) {
    char text[120];
    std::snprintf(text, sizeof text, " (%llu calls of %.2g ms)", static_cast<unsigned long long>(s.calls),
                  1e3 * s.wall_seconds / double(s.calls));
    note += text;
  }
  if (nbody) note += "; the N-body passes ran on all " + std::to_string(threads) + " workers";
  return note + "; the results are the same bits on any count";
}

// The path the main stepper's bodies take (a world of both kinds: the particles').
template <class T>
const char* path_name(const Stepper<T>& stepper, bool rigid) {
  if (rigid) return stepper.fused_rigid() ? "fused" : "rigid";
  if (stepper.fused()) return "fused";
  return stepper.method().kind == MethodKind::linearly_implicit ? "implicit" : "staged";
}

// What ran: the scene, the bodies, the method and where it ran.
template <class T>
void describe_setup(nlohmann::ordered_json& summary, const World<T>& world, const Scene& scene,
                    const RunOptions& o, const StepPlan& plan, const Stepped& s, const RunContext& context) {
  const Stepper<T>& stepper = world.main_stepper();
  summary["scene"] = scene.name;
  summary["bodies"] = body_count(world);
  summary["particles"] = world.particles.size();
  summary["rigid_bodies"] = world.rigid.size();
  summary["method"] = std::string(stepper.method().name);
  if (context.auto_choice) summary["auto"] = *context.auto_choice;
  summary["path"] = path_name(stepper, world.particles.size() == 0 && world.rigid.size() > 0);
  summary["precision"] = std::string(precision_name(scene.precision));
  summary["isa"] = std::string(isa_name(stepper.isa()));
  summary["relaxed_fma"] = o.relaxed_fma;
  summary["threads"] = stepper.threads();
  summary["workers_used"] = stepper.chosen_workers();  // 0: the calling thread alone
  summary["workers_note"] = workers_note(stepper.threads(), stepper.chosen_workers(), plan, s,
                                         world.forces().nbody().has_value());
}

// The steps taken: a fixed dt (as the run's precision holds it), or error control's.
template <class T>
void describe_steps(nlohmann::ordered_json& summary, const World<T>& world, const Scene& scene,
                    const StepPlan& plan, const Stepped& s) {
  const Precision p = scene.precision;
  if (plan.tolerances) {
    const AdaptiveStats& a = s.adaptive;
    summary["rtol"] = number(significant(plan.tolerances->rtol, 15));
    summary["atol"] = number(significant(plan.tolerances->atol, 15));
    summary["steps"] = a.accepted;
    summary["rejected_steps"] = a.rejected;
    // The time covered (the clock starts at 0) over the steps that covered it.
    if (a.accepted > 0) summary["mean_step"] = number(in_precision(world.time() / double(a.accepted), p));
    summary["smallest_step"] = number(in_precision(a.smallest_step, p));
    summary["largest_step"] = number(in_precision(a.largest_step, p));
  } else {
    summary["steps"] = s.done;
    summary["dt"] = number(in_precision(double(T(scene.dt)), p));
  }
  summary["t_final"] = number(in_precision(world.time(), p));
}

// The stiffness, the work done, its speed and the energy.
template <class T>
void describe_cost(nlohmann::ordered_json& summary, const World<T>& world, const StepPlan& plan, const Stepped& s,
                   double initial_energy, Precision p) {
  summary["force_evaluations"] = plan.tolerances ? s.adaptive.evaluations
                                                 : s.done * std::uint64_t(world.main_stepper().method().evaluations());
  const ImplicitStats& implicit = world.main_stepper().implicit_stats();
  if (world.main_stepper().method().kind == MethodKind::linearly_implicit) {
    summary["linear_solves"] = implicit.solves;
    summary["cg_iterations"] = implicit.iterations;
    summary["cg_iterations_max"] = implicit.max_iterations;
    summary["cg_unconverged"] = implicit.unconverged;
  }
  summary["stiffness"] = plan.estimated ? number(measured(plan.stiffness.magnitude)) : nlohmann::ordered_json();
  if (std::isfinite(plan.stable_step)) summary["largest_stable_step"] = number(measured(plan.stable_step));
  summary["wall_seconds"] = number(measured(s.wall_seconds));
  const double body_steps = double(body_count(world)) * double(steps_taken(plan, s));
  summary["body_steps_per_second"] = number(s.wall_seconds > 0 ? measured(body_steps / s.wall_seconds) : 0.0);
  summary["energy_initial"] = number(in_precision(initial_energy, p));
  summary["energy_final"] = s.final_energy ? number(in_precision(*s.final_energy, p)) : nlohmann::ordered_json();
}

// Where the state stopped being finite, for stderr and the summary's error.
std::string blow_up_text(const BlowUp& b) {
  const std::string steps = b.first == b.last
      ? "after step " + std::to_string(b.last)
      : "between steps " + std::to_string(b.first) + " and " + std::to_string(b.last);
  char t[32];
  std::snprintf(t, sizeof t, "%g", b.t);
  return "the state is no longer finite " + steps + " (t = " + t + "): body " + std::to_string(b.body) + ", " + b.field;
}

void describe_end(nlohmann::ordered_json& summary, const Scene& scene, const StepPlan& plan, const Stepped& s) {
  summary["finite"] = !s.blow_up;
  if (s.blow_up) {
    auto& where = summary["first_non_finite"];
    if (s.blow_up->first == s.blow_up->last) {
      where["step"] = s.blow_up->last;
    } else {
      where["between_steps"] = {s.blow_up->first, s.blow_up->last};
    }
    where.update({{"t", number(in_precision(s.blow_up->t, scene.precision))}, {"body", s.blow_up->body},
                  {"field", s.blow_up->field}});
  }
  const int signal = interrupting_signal();
  // A signal while the final energy was summed leaves it out: the run is complete, its
  // summary not.
  if (signal != 0 && (s.done < scene.steps || !s.final_energy)) {
    summary["interrupted"] = signal_name(signal);
    if (plan.tolerances) {
      summary["t_requested"] = number(significant(scene.dt * double(scene.steps), 15));
    } else {
      summary["steps_requested"] = scene.steps;
    }
  }
}

// Whether the run did all it was asked, and from where it resumed. state_crc32c is the digest of
// a checkpoint of the final state: equal values, equal bits (bodies and clocks).
template <class T>
void describe_outcome(nlohmann::ordered_json& summary, const World<T>& world, const Scene& scene, const RunOptions& o,
                      const Stepped& s) {
  summary["complete"] = !s.error && !s.blow_up && (s.done == scene.steps || s.stop_event);
  if (!scene.events.empty()) summary["events"] = s.events;
  if (s.stop_event) summary["stopped_by_event"] = *s.stop_event;
  if (s.error) summary["error"] = *s.error;
  if (!s.error && s.blow_up) summary["error"] = blow_up_text(*s.blow_up);
  if (!s.error && !s.blow_up && interrupting_signal() != 0 && s.done < scene.steps) {
    summary["error"] = "stopped by " + signal_name(interrupting_signal());
  }
  if (s.resumed_at) summary["resumed_from"] = {{"checkpoint", o.checkpoint.resume_path}, {"step", *s.resumed_at}};
  if (!o.checkpoint.path.empty()) summary["checkpoints_written"] = s.checkpoints;
  CheckpointWriter state;
  world.save(state);
  summary["state_crc32c"] = crc_text(state.digest());
}

// The unit of every field that has one and does not name it.
nlohmann::ordered_json units_of(const nlohmann::ordered_json& summary) {
  nlohmann::ordered_json units = nlohmann::ordered_json::object();
  for (const char* key : {"dt", "mean_step", "smallest_step", "largest_step", "t_final", "t_requested",
                          "largest_stable_step"}) {
    if (summary.contains(key)) units[key] = "s";
  }
  if (summary.contains("stiffness")) units["stiffness"] = "1/s";
  return units;
}

template <class T>
nlohmann::ordered_json summarize(const World<T>& world, const Scene& scene, const RunOptions& o,
                                 const StepPlan& plan, const Stepped& s, double initial_energy,
                                 const RunContext& context) {
  nlohmann::ordered_json summary;
  describe_setup(summary, world, scene, o, plan, s, context);
  describe_steps(summary, world, scene, plan, s);
  describe_cost(summary, world, plan, s, initial_energy, scene.precision);
  describe_end(summary, scene, plan, s);
  describe_outcome(summary, world, scene, o, s);
  summary["units"] = units_of(summary);
  return summary;
}

void report_blow_up(const BlowUp& b) {
  std::fprintf(stderr, "kinema: error: %s (try a smaller dt or a more stable method)\n", blow_up_text(b).c_str());
}

// The outputs a signal leaves complete: those asked for.
std::string complete_outputs(const RunOptions& o) {
  if (!o.trajectory_path.empty()) return o.summary_path.empty() && o.quiet ? "the trajectory is" : "the outputs are";
  return o.summary_path.empty() && o.quiet ? "" : "the summary is";
}

// The exit code, with a line on stderr when the run did not end as asked.
int finish(const nlohmann::ordered_json& summary, const Scene& scene, const RunOptions& o, const Stepped& s) {
  if (s.blow_up) {
    report_blow_up(*s.blow_up);
    return 3;
  }
  if (summary.contains("interrupted")) {
    const int signal = interrupting_signal();
    const std::string outputs = complete_outputs(o);
    // Error control stops between its own steps: where it got is a time, not a step of dt.
    const std::string where = summary.contains("t_requested")
        ? "at t = " + summary["t_final"].dump() + " of " + summary["t_requested"].dump()
        : "after step " + std::to_string(s.done) + " of " + std::to_string(scene.steps);
    std::fprintf(stderr, "kinema: stopped by %s %s%s\n", signal_name(signal).c_str(), where.c_str(),
                 outputs.empty() ? "" : ("; " + outputs + " complete to there").c_str());
    return 128 + signal;
  }
  return 0;
}

// The state can be finite while its energy is not (N-body with G = 1e308: the potential
// overflows); the summary's energy there is then null, and this says why. A state that is not
// finite has its own error. Not silenced by -q.
void warn_if_energy_overflows(double initial, double final, bool state_finite) {
  if (!state_finite || (std::isfinite(initial) && std::isfinite(final))) return;
  const bool start = !std::isfinite(initial), end = !std::isfinite(final);
  std::fprintf(stderr, "kinema: warning: the total energy %s overflows double (a force parameter or a mass too "
               "large, or bodies too close without softening): %s null in the summary\n",
               start && end ? "at the start and the end" : start ? "at the start" : "at the end",
               start && end ? "energy_initial and energy_final are" : start ? "energy_initial is" : "energy_final is");
}

// An implicit method takes a scene's springs implicitly; on a scene without them every force
// is explicit (only x' = v stays implicit). Said once (not with -q).
void note_nothing_implicit(const Scene& scene, const RunOptions& o) {
  const Method& method = method_by_name(scene.method);
  if (o.quiet || method.kind != MethodKind::linearly_implicit || !scene.springs.empty()) return;
  const std::string like = &method == &implicit_euler ? " (symplectic Euler's, to rounding)" : "";
  std::fprintf(stderr, "kinema: note: %s takes spring networks implicitly and this scene has none: every force is "
               "explicit, each step its explicit part's%s\n", scene.method.c_str(), like.c_str());
}

// Torques, angular drag, point forces and point springs act on rigid bodies alone: in a scene
// without any they do nothing, which is said (not with -q) rather than left unnoticed.
void note_idle_rotational_terms(const Scene& scene, const RunOptions& o) {
  if (o.quiet || !scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid)) return;
  for (const LocalTerm& term : scene.forces) {
    if (acts_on_rigid_bodies_only(term)) {
      std::fprintf(stderr, "kinema: note: %s acts on rigid bodies only, and this scene has none: it does nothing\n",
                   term_name(term).c_str());
    }
  }
}

// What a summary says of a run that could not start (the world or auto's choice failed).
nlohmann::ordered_json failed_summary(const Scene& scene, const std::string& error) {
  nlohmann::ordered_json summary;
  summary["scene"] = scene.name;
  summary["steps"] = 0;
  summary["complete"] = false;
  summary["error"] = error;
  return summary;
}

// The run from the world on: any error after the world stands still leaves a summary saying
// how far it got, and is thrown on.
template <class T>
int run_typed(const Scene& scene, const RunOptions& o, const RunContext& context, ReportFile& summary_file) {
  const StepperOptions options = stepper_options(o);
  World<T> world = build_world<T>(scene, o, options);
  naming_scene(o.scene_path, [&] { world.watch_events(); });
  double initial_energy = world.total_energy(interrupt_request());
  StepPlan plan;
  Stepped stepped;
  try {
    std::optional<std::uint64_t> trajectory_bytes;
    // Read once, before any step: a scene that is no regular file cannot be checkpointed.
    const std::string fingerprint = o.checkpoint.wanted() ? run_fingerprint(o, scene) : "";
    if (!o.checkpoint.resume_path.empty()) {
      Resumed r = resume(world, scene, o, fingerprint);
      stepped = r.stepped, initial_energy = r.initial_energy, trajectory_bytes = r.trajectory_bytes;
    }
    stepped.fingerprint = fingerprint;
    plan = plan_steps(scene, o, options, double(body_count(world)));
    check_plan(scene, o, plan);
    std::optional<TrajectoryWriter> trajectory;
    if (!o.trajectory_path.empty() && stepped.resumed_at) {
      if (!trajectory_bytes) throw Error(printable(o.checkpoint.resume_path) + ": the checkpoint was taken without --out");
      trajectory.emplace(o.trajectory_path, world.rigid.size() > 0, *trajectory_bytes);
    } else if (!o.trajectory_path.empty()) {
      trajectory.emplace(o.trajectory_path, world.rigid.size() > 0);
    }
    step_scene(world, scene, o, options, plan.tolerances, trajectory, initial_energy, stepped);
  } catch (const std::exception& e) {
    stepped.error = error_text(e);
    try {
      stepped.final_energy = final_energy(world);
      summary_file.write(summarize(world, scene, o, plan, stepped, initial_energy, context));
    } catch (const std::exception&) {  // the summary's own failure: the first error is the one to report
    }
    throw;
  }
  stepped.final_energy = final_energy(world);
  const nlohmann::ordered_json summary = summarize(world, scene, o, plan, stepped, initial_energy, context);
  summary_file.write(summary);
  if (!o.quiet) print_summary(summary);
  if (stepped.final_energy) warn_if_energy_overflows(initial_energy, *stepped.final_energy, world.finite());
  return finish(summary, scene, o, stepped);
}

}  // namespace

int run_scene(const RunOptions& o) {
  check_distinct({{"the scene", o.scene_path}},
                 {{"--out", o.trajectory_path}, {"--summary", o.summary_path}, {"--checkpoint", o.checkpoint.path}});
  check_distinct({{"--resume", o.checkpoint.resume_path}}, {{"--out", o.trajectory_path}, {"--summary", o.summary_path}});
  check_trajectory_resumable(o);
  Scene scene = scene_with_overrides(o);
  check_events(scene, o);
  // Before any work: a path that cannot be written is refused now.
  ReportFile summary_file(o.summary_path, "summary");
  try {
    RunContext context;
    if (scene.method == "auto") context.auto_choice = apply_auto_choice(scene, o.scene_path, !o.precision).record;
    note_nothing_implicit(scene, o);
    note_idle_rotational_terms(scene, o);
    return with_precision(scene.precision,
                          [&]<class T>() { return run_typed<T>(scene, o, context, summary_file); });
  } catch (const std::exception& e) {
    if (!summary_file.written()) {
      try {
        summary_file.write(failed_summary(scene, error_text(e)));
      } catch (const std::exception&) {  // the summary's own failure: the first error is the one to report
      }
    }
    throw;
  }
}

}  // namespace kinema::cli
