// The kinema command-line program.
#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "chart_command.hpp"
#include "kinema/error.hpp"
#include "run_command.hpp"

namespace {

// Options CLI11 fills as text, turned into RunOptions after parsing.
struct TextOptions {
  std::string isa = "auto";
  std::string precision;
};

void add_run_command(CLI::App& app, kinema::cli::RunOptions& o, TextOptions& text) {
  CLI::App* run = app.add_subcommand("run", "Step a scene and print a summary of the run");
  run->add_option("scene", o.scene_path, "Scene file (JSON); see tools/scenes/")->required();
  run->add_option("--method", o.method,
                  "Override the scene's method: euler, midpoint, heun, rk4, symplectic_euler, "
                  "velocity_verlet, or auto (the cheapest method and step for --tolerance)");
  run->add_option("--tolerance", o.tolerance,
                  "With auto: the largest error allowed at the end (length units; radians for "
                  "rigid orientations)")
      ->check(CLI::PositiveNumber);
  run->add_option("--dt", o.dt, "Override the step size (seconds, > 0)")
      ->check(CLI::PositiveNumber);
  // CLI11 2.1 would read "-1" into an unsigned count as 2^64 - 1.
  run->add_option("--steps", o.steps, "Override the number of steps")
      ->check(CLI::Validator(
          [](const std::string& text) {
            return text.find('-') == std::string::npos ? std::string() : "must not be negative";
          },
          "COUNT"));
  run->add_option("--precision", text.precision, "Override the scene's precision: float or double")
      ->check(CLI::IsMember({"float", "double"}));
  run->add_option("--out", o.trajectory_path,
                  "Write the trajectory as CSV (step,t,body,px,py,pz,vx,vy,vz)");
  run->add_option("--every", o.every, "With --out: write every K steps (plus step 0 and the last)")
      ->check(CLI::PositiveNumber);
  run->add_option("--summary", o.summary_path, "Write the run's summary as JSON");
  run->add_option("--isa", text.isa, "Instruction set: auto, scalar, sse2, avx2, avx512")
      ->check(CLI::IsMember({"auto", "scalar", "sse2", "avx2", "avx512"}));
  run->add_option("--threads", o.threads, "Worker threads (0: all cores)")
      ->check(CLI::Range(0u, 1024u));
  run->add_flag("--relaxed-fma", o.relaxed_fma,
                "Scalar and SSE2 paths: multiply then add instead of an exact fused "
                "multiply-add (faster without an FMA unit; results then differ in the last "
                "bits from the AVX2 and AVX-512 paths)");
  run->add_flag("--quiet,-q", o.quiet, "Print nothing on success");
}

void add_chart_command(CLI::App& app, kinema::cli::ChartOptions& o) {
  CLI::App* chart = app.add_subcommand(
      "chart", "Work-precision diagram: error against cost for each method over a range of steps");
  chart->add_option("scene", o.scene_path, "Scene file (JSON)")->required();
  chart->add_option("--methods", o.methods, "Methods to compare (default: all)")->delimiter(',');
  chart->add_option("--dts", o.dts, "Step sizes (default: the scene's dt times 1/8 .. 16)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  chart->add_option("--duration", o.duration, "Simulated time (default: the scene's dt x steps)")
      ->check(CLI::PositiveNumber);
  chart->add_option("--bodies", o.max_bodies, "Bodies sampled from the scene (default 256)")
      ->check(CLI::PositiveNumber);
  chart->add_option("--repeat", o.repeat, "Timed runs per point; the fastest counts (default 3)")
      ->check(CLI::Range(1, 100));
  chart->add_option("--out", o.out, "Output folder (default: charts)");
  chart->add_flag("--quiet,-q", o.quiet, "No progress bar and no summary");
}

void add_stability_command(CLI::App& app, kinema::cli::StabilityOptions& o) {
  CLI::App* s = app.add_subcommand(
      "stability", "Energy error against time, trajectories, and the stability regions");
  s->add_option("scene", o.scene_path, "Scene file (JSON)")->required();
  s->add_option("--methods", o.methods, "Methods to compare (default: all)")->delimiter(',');
  s->add_option("--dt", o.dt, "Step size (default: the scene's)")->check(CLI::PositiveNumber);
  s->add_option("--duration", o.duration, "Simulated time (default: the scene's dt x steps)")
      ->check(CLI::PositiveNumber);
  s->add_option("--bodies", o.max_bodies, "Bodies sampled from the scene (default 256)")
      ->check(CLI::PositiveNumber);
  s->add_option("--out", o.out, "Output folder (default: stability)");
  s->add_flag("--quiet,-q", o.quiet, "No progress bar and no summary");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "kinema: a data-oriented time integrator for particles.\n"
      "Runs a scene (JSON) with a chosen method and reports speed and energy."};
  app.require_subcommand(1);
  kinema::cli::RunOptions options;
  TextOptions text;
  add_run_command(app, options, text);
  kinema::cli::ChartOptions chart;
  add_chart_command(app, chart);
  kinema::cli::StabilityOptions stability;
  add_stability_command(app, stability);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help
    std::fprintf(stderr, "kinema: error: %s (see kinema --help)\n", e.what());
    return 2;
  }
  try {
    options.isa = kinema::isa_by_name(text.isa);
    if (!text.precision.empty()) {
      options.precision =
          text.precision == "float" ? kinema::Precision::single : kinema::Precision::dual;
    }
    if (app.got_subcommand("chart")) return kinema::cli::chart_scene(chart);
    if (app.got_subcommand("stability")) return kinema::cli::stability_scene(stability);
    return kinema::cli::run_scene(options);
  } catch (const kinema::Error& e) {
    std::fprintf(stderr, "kinema: error: %s\n", e.what());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kinema: error: %s\n", e.what());
  }
  return 1;
}
