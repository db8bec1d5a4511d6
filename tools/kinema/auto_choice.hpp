#pragma once
// `kinema run --method auto`: the library's choice applied to the scene, one readable line
// that says what was chosen and why, and its record for the summary.

#include <string>

#include <nlohmann/json.hpp>

#include "kinema/scene.hpp"

namespace kinema::cli {

struct AutoChoice {
  std::string line;               // method, step, precision, and why: one line
  nlohmann::ordered_json record;  // for the summary (the line included, as "choice")
};

// Chooses the method and step for the scene's tolerance (choose_method) and writes them
// into `scene`; `path` names the file in an error. `float_allowed` false keeps the scene's
// precision (the command line named it).
AutoChoice apply_auto_choice(Scene& scene, const std::string& path, bool float_allowed);

}  // namespace kinema::cli
