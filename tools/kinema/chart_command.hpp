#pragma once
// `kinema chart` (work-precision diagrams) and `kinema stability` (where methods fail).

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "kinema/methods.hpp"
#include "kinema/scene.hpp"

namespace kinema::cli {

// What chart and stability share: a scene, the methods, the span, a sample of bodies.
struct SweepOptions {
  std::string scene_path;
  std::vector<std::string> methods;  // empty: every named method
  std::optional<Precision> precision;  // default: the scene's
  std::optional<double> duration;    // default: the scene's dt x steps
  std::size_t max_bodies = 256;      // bodies sampled from the scene
  std::string out;                   // output folder
  bool quiet = false;
};

struct ChartOptions : SweepOptions {
  ChartOptions() { out = "charts"; }
  std::vector<double> dts;  // empty: the scene's dt times 2^-3 .. 2^4
  int repeat = 3;           // timed runs per point (the minimum is kept)
};

int chart_scene(const ChartOptions& options);

struct StabilityOptions : SweepOptions {
  StabilityOptions() { out = "stability"; }
  std::optional<double> dt;  // default: the scene's
};

int stability_scene(const StabilityOptions& options);

// Shared by both commands.
// The scene file in the precision asked for (default its own), with check_scene run in it
// (before any body is built); a scene with a stop event is refused (they run its whole
// duration and watch no events).
Scene load_checked(const std::string& path, std::optional<Precision> precision = std::nullopt);
// Creates the output folder (and its parents); an Error naming it when that fails.
void make_output_folder(const std::filesystem::path& dir);
// The methods named (when none is, every named method the scene's bodies can take; a name
// given twice is an Error).
std::vector<const Method*> pick_methods(const std::vector<std::string>& names, const Scene& scene);
// Steps of about dt over `duration`; kinema::Error past 2^32 steps or below one.
std::uint64_t step_count(double duration, double dt);

}  // namespace kinema::cli
