#pragma once
// `kinema stress`: a large randomized scene (or a scene file) run for a step count or a
// wall-clock budget, reporting throughput per interval, conservation drift, memory and the
// finiteness guard's findings.

#include <cstdint>
#include <optional>
#include <string>

#include "kinema/isa.hpp"
#include "kinema/scene.hpp"
#include "kinema/stepper.hpp"
#include "run_checkpoint.hpp"

namespace kinema::cli {

struct StressOptions {
  std::uint64_t bodies = 100000;           // the built-in scene's size
  std::optional<std::uint64_t> steps;      // default 1000 (or the scene file's)
  std::optional<double> seconds;           // wall-clock budget instead of a step count
  unsigned threads = 0;                    // 0: all hardware threads
  std::optional<std::string> method;      // default rk4 (or the scene file's)
  std::optional<Precision> precision;      // default float (or the scene file's)
  std::optional<double> dt;                // default kStressDt (or the scene file's)
  std::string scene_path;                  // empty: the built-in randomized scene
  std::uint64_t seed = 1;
  std::string report_path;                 // empty: no report file
  FiniteGuard guard = FiniteGuard::check;
  double max_speed = StepperOptions{}.max_speed;
  double max_angular_speed = StepperOptions{}.max_angular_speed;
  double interval = 1;                     // seconds of wall clock per throughput interval
  Isa isa = Isa::automatic;
  bool quiet = false;
  CheckpointOptions checkpoint;
};

// Returns the exit code: 0, 3 when a state stopped being finite, 128 + N on signal N.
int stress(const StressOptions& options);
// What stress checks before any step (kinema::Error for what it refuses), and, when the
// scene is at most `most_bodies` body-evaluations, its bodies and steppers built: for fuzzing.
void check_stress(const StressOptions& options, std::size_t most_bodies);

// "off", "check", "clamp"; kinema::Error for any other name.
FiniteGuard guard_by_name(const std::string& name);

}  // namespace kinema::cli
