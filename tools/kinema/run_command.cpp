#include "run_command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <optional>

#include <nlohmann/json.hpp>

#include "kinema/kinema.hpp"
#include "progress.hpp"
#include "trajectory.hpp"

namespace kinema::cli {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

Scene scene_with_overrides(const RunOptions& o) {
  Scene scene = load_scene(o.scene_path);
  if (o.method) scene.method = *o.method;
  if (o.tolerance) scene.tolerance = *o.tolerance;
  if (o.dt) scene.dt = *o.dt;
  if (o.steps) scene.steps = *o.steps;
  if (o.precision) scene.precision = *o.precision;
  if (!(std::isfinite(scene.dt) && scene.dt > 0)) throw Error("dt must be positive and finite");
  if (scene.method != "auto") method_by_name(scene.method);
  if (scene.method == "auto" && !scene.tolerance) {
    throw Error("method auto needs a tolerance (the scene's \"tolerance\" or --tolerance)");
  }
  return scene;
}

namespace {

void print_summary(const nlohmann::ordered_json& summary) {
  std::printf("kinema run: %s\n", summary["scene"].get<std::string>().c_str());
  for (const auto& [key, value] : summary.items()) {
    if (key == "scene") continue;
    std::printf("  %-22s %s\n", key.c_str(),
                value.is_string() ? value.get<std::string>().c_str() : value.dump().c_str());
  }
}

// What happened before stepping that the summary reports.
struct RunContext {
  std::optional<nlohmann::ordered_json> auto_choice;
};

template <class T>
int run_typed(const Scene& scene, const RunOptions& o, const RunContext& context) {
  StepperOptions options;
  options.isa = o.isa;
  options.threads = o.threads;
  options.relaxed_fma = o.relaxed_fma;
  World<T> world = [&] {
    try {
      return World<T>(scene, method_by_name(scene.method), options);
    } catch (const Error& e) {  // bodies or forces the precision cannot hold: name the file
      throw Error(o.scene_path + ": " + e.what());
    }
  }();
  const T h = T(scene.dt);
  const double initial_energy = world.total_energy();

  double wall_seconds = 0;  // stepping only: loading and writing are not timed
  Progress progress("kinema run", o.quiet);
  std::uint64_t done = 0;
  auto timed_advance = [&](std::uint64_t n) {
    const auto start = Clock::now();
    world.advance(h, n);
    wall_seconds += std::chrono::duration<double>(Clock::now() - start).count();
    done += n;
    progress.update(double(done) / double(std::max<std::uint64_t>(1, scene.steps)));
  };
  if (o.trajectory_path.empty()) {
    // In chunks, for the progress bar: the same bits as one call.
    const std::uint64_t chunk = std::max<std::uint64_t>(1, scene.steps / 100);
    for (std::uint64_t step = 0; step < scene.steps; step += chunk) {
      timed_advance(std::min(chunk, scene.steps - step));
    }
  } else {
    TrajectoryWriter trajectory(o.trajectory_path, world.rigid.size() > 0);
    trajectory.write(0, world.time(), world.particles, world.rigid);
    for (std::uint64_t step = 0; step < scene.steps;) {
      const std::uint64_t n = std::min(o.every, scene.steps - step);
      timed_advance(n);
      step += n;
      trajectory.write(step, world.time(), world.particles, world.rigid);
    }
    trajectory.close();
  }

  progress.finish();
  const bool finite = world.finite();
  const std::size_t bodies = world.particles.size() + world.rigid.size();
  const double body_steps = double(bodies) * double(scene.steps);
  const Stepper<T>& stepper = world.stepper();
  nlohmann::ordered_json summary;
  summary["scene"] = scene.name;
  summary["bodies"] = bodies;
  summary["particles"] = world.particles.size();
  summary["rigid_bodies"] = world.rigid.size();
  summary["steps"] = scene.steps;
  summary["method"] = std::string(stepper.method().name);
  summary["path"] = stepper.fused() ? "fused" : "staged";
  summary["dt"] = scene.dt;
  summary["t_final"] = world.time();
  summary["precision"] = std::string(precision_name(scene.precision));
  summary["isa"] = std::string(isa_name(stepper.isa()));
  summary["relaxed_fma"] = o.relaxed_fma;
  summary["threads"] = stepper.threads();
  summary["wall_seconds"] = wall_seconds;
  summary["body_steps_per_second"] = wall_seconds > 0 ? body_steps / wall_seconds : 0.0;
  summary["energy_initial"] = initial_energy;
  summary["energy_final"] = world.total_energy();
  summary["finite"] = finite;
  if (context.auto_choice) summary["auto"] = *context.auto_choice;

  if (!o.summary_path.empty()) {
    std::ofstream out(o.summary_path);
    out << summary.dump(2) << '\n';
    if (!out) throw Error(o.summary_path + ": cannot write the summary");
  }
  if (!o.quiet) print_summary(summary);
  if (!finite) {
    std::fprintf(stderr, "kinema: error: the state is no longer finite after %llu steps "
                         "(try a smaller dt or a more stable method)\n",
                 static_cast<unsigned long long>(scene.steps));
    return 3;
  }
  return 0;
}

}  // namespace

int run_scene(const RunOptions& o) {
  Scene scene = scene_with_overrides(o);
  std::optional<nlohmann::ordered_json> choice;
  if (scene.method == "auto") {
    const auto start = Clock::now();
    const MethodChoice c = choose_method(scene, *scene.tolerance);
    choice = nlohmann::ordered_json{
        {"method", std::string(c.method->name)}, {"dt", c.dt}, {"steps", c.steps},
        {"tolerance", *scene.tolerance}, {"estimated_error", c.estimated_error},
        {"seconds", std::chrono::duration<double>(Clock::now() - start).count()},
        {"reason", c.reason}};
    scene.method = std::string(c.method->name);
    scene.dt = c.dt;
    scene.steps = c.steps;
  }
  const RunContext context{choice};
  return scene.precision == Precision::single ? run_typed<float>(scene, o, context)
                                              : run_typed<double>(scene, o, context);
}

}  // namespace kinema::cli
