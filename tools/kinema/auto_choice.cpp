#include "auto_choice.hpp"

#include <chrono>
#include <cstdio>
#include <limits>

#include "kinema/accuracy.hpp"
#include "kinema/error.hpp"
#include "interrupt.hpp"
#include "numbers.hpp"

namespace kinema::cli {
namespace {

std::string format(const char* pattern, auto... values) {
  char text[320];
  std::snprintf(text, sizeof text, pattern, values...);
  return text;
}

// The step the choice runs with: error control with its tolerances, or a fixed step.
std::string step_text(const MethodChoice& c) {
  const std::string name(c.method->name);
  if (c.step_tolerance) return format("%s with error control (rtol = atol = %g)", name.c_str(), *c.step_tolerance);
  return format("%s at dt %.4g s (%llu steps)", name.c_str(), c.dt, static_cast<unsigned long long>(c.steps));
}

// The cheapest fixed-step candidate other than the choice, if any.
const MethodChoice::Candidate* runner_up(const MethodChoice& c) {
  const MethodChoice::Candidate* best = nullptr;
  double cost = std::numeric_limits<double>::infinity();
  for (const auto& candidate : c.candidates) {
    if (!c.step_tolerance && candidate.method == c.method) continue;
    if (candidate.evaluations < cost) cost = candidate.evaluations, best = &candidate;
  }
  return best;
}

// Method, step, precision and why, every cost in force evaluations.
std::string choice_line(const MethodChoice& c, Precision scene_precision, double tolerance, double duration) {
  std::string line = step_text(c) + " in " + std::string(precision_name(c.precision)) +
                     format(": %.0f force evaluations, the fewest found for an error under %g over %g s "
                            "(estimated %.2g)",
                            c.evaluations, tolerance, duration, c.estimated_error);
  if (const auto* next = runner_up(c)) {
    line += format("; next cheapest: %s with fixed steps, %.0f force evaluations", std::string(next->method->name).c_str(),
                   next->evaluations);
  }
  if (c.method->kind == MethodKind::linearly_implicit) line += "; each iteration of its solves counted as an evaluation";
  if (c.precision != scene_precision) line += "; float's round-off stays under a tenth of the tolerance";
  return line;
}

nlohmann::ordered_json choice_record(const MethodChoice& c, double tolerance, double seconds) {
  nlohmann::ordered_json j{{"method", std::string(c.method->name)}};
  if (c.step_tolerance) {
    j["rtol"] = j["atol"] = number(significant(*c.step_tolerance, 15));
  } else {
    j.update({{"dt", number(significant(c.dt, 15))}, {"steps", c.steps}});
  }
  j.update({{"precision", std::string(precision_name(c.precision))},
            {"force_evaluations", std::uint64_t(c.evaluations)},
            {"tolerance", number(significant(tolerance, 15))},
            {"estimated_error", number(measured(c.estimated_error))},
            {"seconds", number(measured(seconds))}});
  j["candidates"] = nlohmann::ordered_json::array();
  for (const auto& candidate : c.candidates) {
    j["candidates"].push_back({{"method", std::string(candidate.method->name)},
                               {"steps", candidate.steps},
                               {"force_evaluations", std::uint64_t(candidate.evaluations)}});
  }
  return j;
}

MethodChoice choose(const Scene& scene, const std::string& path, bool float_allowed) {
  try {
    return choose_method(scene, *scene.tolerance, interrupt_request(), float_allowed);
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
}

}  // namespace

AutoChoice apply_auto_choice(Scene& scene, const std::string& path, bool float_allowed) {
  const auto start = std::chrono::steady_clock::now();
  const MethodChoice c = choose(scene, path, float_allowed);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  AutoChoice choice;
  choice.line = choice_line(c, scene.precision, *scene.tolerance, scene.dt * double(scene.steps));
  choice.record = choice_record(c, *scene.tolerance, seconds);
  choice.record["choice"] = choice.line;
  if (c.step_tolerance) {
    scene.rtol = scene.atol = *c.step_tolerance;  // the duration stays dt x steps
  } else {
    scene.dt = c.dt;
    scene.steps = c.steps;
  }
  scene.method = std::string(c.method->name);
  scene.precision = c.precision;
  return choice;
}

}  // namespace kinema::cli
