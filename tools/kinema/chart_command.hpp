#pragma once
// `kinema chart` (work-precision diagrams) and `kinema stability` (where methods fail).

#include <optional>
#include <string>
#include <vector>

namespace kinema::cli {

struct ChartOptions {
  std::string scene_path;
  std::vector<std::string> methods;  // empty: every built-in method
  std::vector<double> dts;           // empty: the scene's dt times 2^-3 .. 2^4
  std::optional<double> duration;    // default: the scene's dt x steps
  std::size_t max_bodies = 256;      // bodies sampled from the scene
  int repeat = 3;                    // timed runs per point (the minimum is kept)
  std::string out = "charts";
  bool quiet = false;
};

int chart_scene(const ChartOptions& options);

struct StabilityOptions {
  std::string scene_path;
  std::vector<std::string> methods;
  std::optional<double> dt;
  std::optional<double> duration;
  std::size_t max_bodies = 256;
  std::string out = "stability";
  bool quiet = false;
};

int stability_scene(const StabilityOptions& options);

}  // namespace kinema::cli
