#pragma once
// `kinema run`: load a scene, step it, report.

#include <cstdint>
#include <optional>
#include <string>

#include "kinema/isa.hpp"
#include "kinema/scene.hpp"
#include "run_checkpoint.hpp"

namespace kinema::cli {

struct RunOptions {
  std::string scene_path;
  std::optional<std::string> method;
  std::optional<double> dt;
  std::optional<std::uint64_t> steps;
  std::optional<double> tolerance;
  std::optional<double> rtol, atol;  // error control (embedded pairs)
  std::optional<Precision> precision;
  std::string trajectory_path;  // empty: no trajectory
  std::uint64_t every = 1;
  std::string summary_path;     // empty: no summary file
  Isa isa = Isa::automatic;
  unsigned threads = 0;         // 0: all hardware threads
  bool relaxed_fma = false;     // scalar and SSE2 paths: multiply then add
  std::optional<double> implicit_tolerance;  // implicit methods' linear solves (StepperOptions)
  std::optional<int> implicit_iterations;
  std::optional<std::string> implicit_preconditioner;  // automatic (unset), jacobi, multigrid
  bool quiet = false;
  bool strict = false;          // a dt past the largest stable step is an error, not a warning
  CheckpointOptions checkpoint;
};

// Returns the process exit code: 0, or 3 when the state stopped being finite.
int run_scene(const RunOptions& options);

// The scene file with the command line's overrides applied (and checked).
Scene scene_with_overrides(const RunOptions& options);

}  // namespace kinema::cli
