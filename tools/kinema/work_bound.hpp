#pragma once
// The most work chart and stability take on a scene, checked before their first run: on the
// 4096-body Plummer cluster their defaults would take hours.

#include <cstdio>
#include <string>

#include "kinema/error.hpp"
#include "kinema/scene.hpp"

namespace kinema::cli {

// 2^40 body-evaluations (kinema::evaluation_cost): tens of minutes on one core.
inline constexpr double kMostBodyEvaluations = 0x1p40;

// Throws kinema::Error when `evaluations` force evaluations of the scene pass the bound,
// naming what they come to and `hint` (the options that make them fewer).
inline void check_work(const std::string& path, const char* command, double evaluations, const Scene& scene,
                       const char* hint) {
  const double work = evaluations * evaluation_cost(scene);
  if (!(work > kMostBodyEvaluations)) return;
  char text[320];
  std::snprintf(text, sizeof text,
                ": %s would take about %.2g body-evaluations (%.3g force evaluations of %.3g each), more than the "
                "%.2g it may spend; %s",
                command, work, evaluations, evaluation_cost(scene), kMostBodyEvaluations, hint);
  throw Error(printable(path) + text);
}

}  // namespace kinema::cli
