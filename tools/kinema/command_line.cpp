#include "command_line.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <string_view>
#include <type_traits>
#include <vector>

#include <CLI/CLI.hpp>

#include "kinema/error.hpp"
#include "kinema/version.hpp"

namespace kinema::cli {
namespace {

// CLI11 2.1 reads integers in base 0 ("010" is 8, "0x10" is 16) and wraps unsigned ones
// ("-1" is 2^64 - 1): counts are checked here as decimal text and handed on without
// leading zeros, so CLI11 reads the number the user wrote.
CLI::Validator decimal(std::uint64_t least, std::uint64_t most) {
  const std::string range = std::to_string(least) + " to " + std::to_string(most);
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        std::uint64_t value = 0;
        const char* end = text.data() + text.size();
        const auto [stop, error] = std::from_chars(text.data(), end, value, 10);
        if (text.empty() || stop != end || text.find_first_not_of("0123456789") != std::string::npos) {
          return "expected a decimal integer from " + range + ", got '" + printable(text) + "'";
        }
        if (error != std::errc() || value < least || value > most) {
          return "expected " + range + ", got " + printable(text);
        }
        text = std::to_string(value);
        return {};
      },
      "INT in [" + range + "]");
}

// A decimal number that `accepts`, handed on as an exact hexadecimal float: CLI11 2.1
// converts through long double, which would round some decimal texts twice. `expected` says
// what it takes ("expected <expected>, got '...'").
template <class Accepts>
CLI::Validator exact_number(Accepts accepts, const std::string& expected, const std::string& shown) {
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        double value = 0;
        const char* end = text.data() + text.size();
        const auto [stop, error] = std::from_chars(text.data(), end, value);
        if (text.empty() || stop != end || error != std::errc() || !accepts(value)) {
          return "expected " + expected + ", got '" + printable(text) + "'";
        }
        char exact[40];
        std::snprintf(exact, sizeof exact, "%a", value);
        text = exact;
        return {};
      },
      shown);
}

// A finite number > 0 (CLI11's PositiveNumber lets inf through and prints its range with 309
// digits).
const CLI::Validator positive_finite = exact_number(
    [](double x) { return std::isfinite(x) && x > 0; }, "a finite number > 0", "NUMBER > 0");

// A number in [least, most] (CLI11's Range lets NaN through and prints its bounds to six
// decimals: 1e-300 as 0.000000).
CLI::Validator number_in(double least, double most) {
  char range[64];
  std::snprintf(range, sizeof range, "%g to %g", least, most);
  return exact_number([=](double x) { return x >= least && x <= most; }, std::string("a number from ") + range,
                      std::string("NUMBER in [") + range + "]");
}

const CLI::Validator not_empty(
    [](std::string& text) -> std::string { return text.empty() ? "expected a path, got ''" : ""; },
    "PATH");

constexpr std::uint64_t kMaxCount = std::numeric_limits<std::uint64_t>::max();

void add_checkpoint_options(CLI::App& command, CheckpointOptions& o) {
  auto* path = command.add_option("--checkpoint", o.path,
                                  "Save the run to FILE (written whole) every --checkpoint-every seconds, at the "
                                  "end and when a signal stops it")
                   ->check(not_empty);
  command.add_option("--checkpoint-every", o.every, "Seconds of wall clock between checkpoints (default 60)")
      ->transform(positive_finite)
      ->needs(path);
  command.add_option("--resume", o.resume_path,
                     "Go on from a checkpoint of this run (the same scene and options): the results are "
                     "the bits of a run never stopped")
      ->check(not_empty);
}

void add_run_command(CLI::App& app, RunOptions& o, std::string& isa, std::string& precision) {
  CLI::App* run = app.add_subcommand("run", "Step a scene and print a summary of the run");
  run->add_option("scene", o.scene_path, "Scene file (JSON); see tools/scenes/")
      ->required()
      ->check(not_empty);
  run->add_option("--method", o.method,
                  "Override the scene's method: euler, midpoint, heun, rk4, symplectic_euler, "
                  "velocity_verlet, bs3, dopri5, rk6, implicit_euler, ros2 (implicit: particles with "
                  "springs, fixed steps), or auto (the cheapest method and step for --tolerance: "
                  "explicit, or implicit where stiff springs set every explicit step)");
  run->add_option("--tolerance", o.tolerance,
                  "With auto: the largest error allowed at the end (length units; radians for "
                  "rigid orientations)")
      ->transform(positive_finite);
  run->add_option("--dt", o.dt, "Override the step size (seconds, > 0)")->transform(positive_finite);
  run->add_option("--rtol", o.rtol,
                  "With bs3 or dopri5: control each step's error, relative part (the run then "
                  "chooses its steps over the scene's duration, dt x steps)")
      ->transform(positive_finite);
  run->add_option("--atol", o.atol, "With bs3 or dopri5: control each step's error, absolute part")
      ->transform(positive_finite);
  run->add_option("--steps", o.steps, "Override the number of steps")->transform(decimal(0, kMaxCount));
  run->add_option("--precision", precision, "Override the scene's precision: float or double")
      ->check(CLI::IsMember({"float", "double"}));
  auto* out = run->add_option("--out", o.trajectory_path,
                               "Write the trajectory as CSV (step,t,body,px,py,pz,vx,vy,vz)")
                   ->check(not_empty);
  run->add_option("--every", o.every, "With --out: write every K steps (plus step 0 and the last)")
      ->transform(decimal(1, kMaxCount))
      ->needs(out);
  run->add_option("--summary", o.summary_path, "Write the run's summary as JSON")->check(not_empty);
  run->add_option("--isa", isa, "Instruction set: auto, scalar, sse2, avx2, avx512")
      ->check(CLI::IsMember({"auto", "scalar", "sse2", "avx2", "avx512"}));
  run->add_option("--threads", o.threads,
                  "Worker threads (0: all cores; more than the machine has are not started)")
      ->transform(decimal(0, 1024));
  run->add_option("--implicit-tolerance", o.implicit_tolerance,
                  "Implicit methods: each linear solve stops at this residual relative to its right side "
                  "(default 1e-3 in float, 1e-10 in double)")
      ->transform(number_in(1e-300, 0.5));
  run->add_option("--implicit-iterations", o.implicit_iterations,
                  "Implicit methods: the most conjugate-gradient iterations a solve takes (default 1000)")
      ->transform(decimal(1, 1 << 30));
  run->add_option("--implicit-preconditioner", o.implicit_preconditioner,
                  "Implicit methods: automatic (multigrid for spring networks of 1024 bodies or more, "
                  "else Jacobi), jacobi or multigrid")
      ->check(CLI::IsMember({"automatic", "jacobi", "multigrid"}));
  run->add_flag("--relaxed-fma", o.relaxed_fma,
                "Scalar and SSE2 paths: multiply then add instead of an exact fused "
                "multiply-add (faster without an FMA unit; results then differ in the last "
                "bits from the AVX2 and AVX-512 paths)");
  run->add_flag("--quiet,-q", o.quiet,
                "No summary and no progress bar (a warning that the step is past the stable one, "
                "and errors, still go to stderr)");
  run->add_flag("--strict", o.strict,
                "Refuse (exit 1) a dt past the method's largest stable step on this scene, which "
                "otherwise is a warning");
  add_checkpoint_options(*run, o.checkpoint);
}

// A comma-separated list, each item checked (and rewritten) by `each` where one is given.
// CLI11's own delimiter drops empty items, so "euler,,rk4" read as "euler,rk4" and ",euler"
// as "euler": a list with an empty item is refused here.
template <class Item>
CLI::Option* add_list_option(CLI::App& command, const std::string& name, std::vector<Item>& into,
                             const std::string& help, const CLI::Validator* each = nullptr) {
  return command.add_option_function<std::string>(
      name,
      [&into, name, each](const std::string& text) {
        into.clear();
        for (std::size_t at = 0;;) {
          const std::size_t comma = std::min(text.find(',', at), text.size());
          std::string item = text.substr(at, comma - at);
          if (item.empty()) {
            throw CLI::ValidationError(name, "an empty item in '" + printable(text) +
                                                 "' (a comma at an end, or two together)");
          }
          if (each != nullptr) {
            if (const std::string why = (*each)(item); !why.empty()) throw CLI::ValidationError(name, why);
          }
          if constexpr (std::is_same_v<Item, double>) {
            into.push_back(std::strtod(item.c_str(), nullptr));  // `each` wrote it exactly
          } else {
            into.push_back(item);
          }
          if (comma == text.size()) return;
          at = comma + 1;
        }
      },
      help);
}

// The options chart and stability share.
void add_sweep_options(CLI::App& command, SweepOptions& o) {
  command.add_option("scene", o.scene_path, "Scene file (JSON)")->required()->check(not_empty);
  command.add_option_function<std::string>(
             "--precision",
             [&o](const std::string& p) { o.precision = p == "float" ? Precision::single : Precision::dual; },
             "Override the scene's precision: float or double")
      ->check(CLI::IsMember({"float", "double"}));
  add_list_option(command, "--methods", o.methods,
                  "Methods to compare, comma-separated (default: the explicit ones the bodies take; implicit ones when named)");
  command.add_option("--duration", o.duration, "Simulated time (default: the scene's dt x steps)")
      ->transform(positive_finite);
  command.add_option("--bodies", o.max_bodies, "Bodies sampled from the scene (default 256)")
      ->transform(decimal(1, std::uint64_t(1) << 32));
  command.add_option("--out", o.out, "Output folder (default: " + o.out + ")")->check(not_empty);
  command.add_flag("--quiet,-q", o.quiet, "No progress bar and no summary");
}

void add_chart_command(CLI::App& app, ChartOptions& o) {
  CLI::App* chart = app.add_subcommand(
      "chart", "Work-precision diagram: error against cost for each method over a range of steps");
  add_sweep_options(*chart, o);
  add_list_option(*chart, "--dts", o.dts,
                  "Step sizes, comma-separated (default: the scene's dt times 1/8 .. 16)", &positive_finite);
  chart->add_option("--repeat", o.repeat, "Timed runs per point; the fastest counts (default 3)")
      ->transform(decimal(1, 100));
}

void add_stability_command(CLI::App& app, StabilityOptions& o) {
  CLI::App* s = app.add_subcommand(
      "stability", "Energy error against time, trajectories, and the stability regions");
  add_sweep_options(*s, o);
  s->add_option("--dt", o.dt, "Step size (default: the scene's)")->transform(positive_finite);
}

void add_stress_command(CLI::App& app, StressOptions& o, std::string& isa, std::string& precision,
                        std::string& guard) {
  CLI::App* s = app.add_subcommand(
      "stress", "A large randomized scene (or --scene) run long: throughput, drift, memory, finiteness");
  s->add_option("--bodies", o.bodies, "Bodies of the built-in scene (default 100000)")
      ->transform(decimal(1, std::uint64_t(1) << 30));
  auto* steps = s->add_option("--steps", o.steps, "Steps to run (default 1000, or the scene file's)")
                    ->transform(decimal(1, kMaxCount));
  s->add_option("--seconds", o.seconds, "Run for this long (wall clock) instead of a step count")
      ->transform(positive_finite)
      ->excludes(steps);
  s->add_option("--threads", o.threads, "Worker threads (0: all cores)")->transform(decimal(0, 1024));
  s->add_option("--method", o.method, "Method (default rk4, or the scene file's)");
  s->add_option("--precision", precision, "float (default) or double")
      ->check(CLI::IsMember({"float", "double"}));
  s->add_option("--dt", o.dt, "Step size (default 0.001, or the scene file's)")->transform(positive_finite);
  auto* scene = s->add_option("--scene", o.scene_path, "Stress a scene file instead of the built-in scene")
                    ->check(not_empty);
  s->add_option("--seed", o.seed, "Seed of the built-in scene (default 1)")
      ->transform(decimal(0, kMaxCount))
      ->excludes(scene);
  s->get_option("--bodies")->excludes(scene);
  s->add_option("--report", o.report_path, "Write the report as JSON")->check(not_empty);
  s->add_option("--guard", guard,
                "Finiteness guard: check (default: stop at the step that made a value not finite, "
                "keep the state before it), clamp (also hold speeds to --max-speed and "
                "--max-angular-speed: changes the physics), off")
      ->check(CLI::IsMember({"off", "check", "clamp"}));
  s->add_option("--max-speed", o.max_speed, "With --guard clamp: the largest speed (default 500)")
      ->transform(positive_finite);
  s->add_option("--max-angular-speed", o.max_angular_speed,
                "With --guard clamp: the largest angular speed, rad/s (default 50)")
      ->transform(positive_finite);
  s->add_option("--interval", o.interval, "Seconds per throughput interval (default 1)")
      ->transform(positive_finite);
  s->add_option("--isa", isa, "Instruction set: auto, scalar, sse2, avx2, avx512")
      ->check(CLI::IsMember({"auto", "scalar", "sse2", "avx2", "avx512"}));
  s->add_flag("--quiet,-q", o.quiet, "Print nothing but errors");
  add_checkpoint_options(*s, o.checkpoint);
}

}  // namespace

std::unique_ptr<CLI::App> make_app(CommandLine& out) {
  auto app = std::make_unique<CLI::App>(
      "kinema: a data-oriented time integrator for particles and rigid bodies.\n"
      "Runs a scene (JSON) with a chosen method and reports speed and energy.");
  app->require_subcommand(1);
  app->set_version_flag("--version", std::string("kinema ") + version, "Print the version and exit");
  add_run_command(*app, out.run, out.isa, out.precision);
  add_chart_command(*app, out.chart);
  add_stability_command(*app, out.stability);
  add_stress_command(*app, out.stress, out.isa, out.precision, out.guard);
  return app;
}

std::string help_command(const CLI::App& app) {
  const std::vector<CLI::App*> parsed = app.get_subcommands();
  return parsed.empty() ? "kinema --help" : "kinema " + parsed.front()->get_name() + " --help";
}

void parse_command_line(CLI::App& app, CommandLine& out, int argc, const char* const* argv) {
  // A first word that is no command and no option: named, where CLI11 would only say that a
  // command is required.
  constexpr std::array<std::string_view, 4> commands{"run", "chart", "stability", "stress"};
  if (argc > 1 && argv[1][0] != '-' && std::find(commands.begin(), commands.end(), argv[1]) == commands.end()) {
    throw CLI::ValidationError("unknown command '" + printable(argv[1]) + "': run, chart, stability or stress");
  }
  app.parse(argc, argv);
  for (const std::string_view name : commands) {
    if (app.got_subcommand(std::string(name))) out.command = name;
  }
  // Both were checked against their lists while parsing.
  out.run.isa = out.stress.isa = isa_by_name(out.isa);
  if (!out.precision.empty()) {
    out.run.precision = out.stress.precision = out.precision == "float" ? Precision::single : Precision::dual;
  }
  out.stress.guard = guard_by_name(out.guard);
  if (app.got_subcommand("stress") && out.stress.guard != FiniteGuard::clamp) {
    const CLI::App& stress = *app.get_subcommand("stress");
    for (const char* limit : {"--max-speed", "--max-angular-speed"}) {
      if (stress.count(limit) > 0) throw CLI::ValidationError(limit, "holds speeds under --guard clamp only");
    }
  }
}

}  // namespace kinema::cli
