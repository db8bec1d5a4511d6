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
#include "trajectory.hpp"

namespace kinema::cli {
namespace {

using Clock = std::chrono::steady_clock;

Scene scene_with_overrides(const RunOptions& o) {
  Scene scene = load_scene(o.scene_path);
  if (o.method) scene.method = *o.method;
  if (o.dt) scene.dt = *o.dt;
  if (o.steps) scene.steps = *o.steps;
  if (o.precision) scene.precision = *o.precision;
  if (!(std::isfinite(scene.dt) && scene.dt > 0)) throw Error("dt must be positive and finite");
  return scene;
}

void print_summary(const nlohmann::ordered_json& summary) {
  std::printf("kinema run: %s\n", summary["scene"].get<std::string>().c_str());
  for (const auto& [key, value] : summary.items()) {
    if (key == "scene") continue;
    std::printf("  %-22s %s\n", key.c_str(),
                value.is_string() ? value.get<std::string>().c_str() : value.dump().c_str());
  }
}

template <class T>
int run_typed(const Scene& scene, const RunOptions& o) {
  ParticleSet<T> bodies = make_particles<T>(scene);
  StepperOptions stepper_options;
  stepper_options.isa = o.isa;
  stepper_options.threads = o.threads;
  stepper_options.relaxed_fma = o.relaxed_fma;
  Stepper<T> stepper(make_forces<T>(scene), method_by_name(scene.method), stepper_options);
  const T h = T(scene.dt);
  const EnergyReport initial = energy(bodies, stepper.forces());

  double wall_seconds = 0;  // stepping only: loading and writing are not timed
  auto timed_advance = [&](std::uint64_t n) {
    const auto start = Clock::now();
    stepper.advance(bodies, h, n);
    wall_seconds += std::chrono::duration<double>(Clock::now() - start).count();
  };
  if (o.trajectory_path.empty()) {
    timed_advance(scene.steps);
  } else {
    TrajectoryWriter trajectory(o.trajectory_path);
    trajectory.write(0, stepper.time(), bodies);
    for (std::uint64_t step = 0; step < scene.steps;) {
      const std::uint64_t n = std::min(o.every, scene.steps - step);
      timed_advance(n);
      step += n;
      trajectory.write(step, stepper.time(), bodies);
    }
    trajectory.close();
  }

  const EnergyReport final_energy = energy(bodies, stepper.forces());
  const bool finite = all_finite(bodies);
  const double body_steps = double(bodies.size()) * double(scene.steps);
  nlohmann::ordered_json summary;
  summary["scene"] = scene.name;
  summary["bodies"] = bodies.size();
  summary["steps"] = scene.steps;
  summary["method"] = std::string(stepper.method().name);
  summary["path"] = stepper.fused() ? "fused" : "staged";
  summary["dt"] = scene.dt;
  summary["t_final"] = stepper.time();
  summary["precision"] = std::string(precision_name(scene.precision));
  summary["isa"] = std::string(isa_name(stepper.isa()));
  summary["relaxed_fma"] = o.relaxed_fma;
  summary["threads"] = stepper.threads();
  summary["wall_seconds"] = wall_seconds;
  summary["body_steps_per_second"] = wall_seconds > 0 ? body_steps / wall_seconds : 0.0;
  summary["energy_initial"] = initial.total();
  summary["energy_final"] = final_energy.total();
  summary["finite"] = finite;

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
  const Scene scene = scene_with_overrides(o);
  return scene.precision == Precision::single ? run_typed<float>(scene, o)
                                              : run_typed<double>(scene, o);
}

}  // namespace kinema::cli
