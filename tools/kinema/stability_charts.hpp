#pragma once
// The charts of `kinema stability`: each writes the data files it plots (or reads those the
// command wrote) and renders through gnuplot into the output folder.

#include <complex>
#include <filesystem>
#include <string>
#include <vector>

#include "kinema/methods.hpp"

namespace kinema::cli {

// The relative energy error against time per method, from energy_METHOD.dat (t, |error|).
void render_energy_chart(const std::filesystem::path& dir, const std::string& scene, double dt,
                         const std::vector<const Method*>& methods);

// The path of body 0 in the x-y plane per method, from path_METHOD.dat (x, y).
void render_trajectory_chart(const std::filesystem::path& dir, const std::string& scene,
                             const std::vector<const Method*>& methods);

// An explicit Runge-Kutta method's stability region: the boundary |R(z)| = 1 as the roots
// of R(z) = e^(i phi) at evenly spaced phi, and the measured limit on the negative real axis.
struct RegionBoundary {
  std::string method;
  std::vector<double> polynomial;  // R's coefficients, constant first
  std::vector<std::vector<std::complex<double>>> roots;  // per phi, in any order
  double measured_limit;
};

// Writes region_METHOD.dat (the boundary traced into curves) and threshold_METHOD.dat, and
// renders stability_region.
void render_region_chart(const std::filesystem::path& dir, const std::vector<RegionBoundary>& regions);

struct StepLimit {
  std::string method;
  double predicted, measured;  // 0 or infinity when there is no limit to draw
};

// Writes step_limits.dat and renders step_limits: each method's predicted and measured
// largest stable step against the scene's dt. `stiffness`: |lambda| at the start, 1/s.
void render_step_limits(const std::filesystem::path& dir, const std::vector<StepLimit>& limits,
                        double stiffness, double dt);

}  // namespace kinema::cli
