#pragma once
// Numbers as the summaries show them: to the digits they carry, so that a JSON summary and
// the printed one read the same, without the noise of the last binary digits (a wall time
// summed from chunks, a tolerance divided by ten) and without digits a float never had.

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "kinema/error.hpp"
#include "kinema/scene.hpp"

namespace kinema::cli {

// Measured or estimated quantities (times, rates, stiffness): four significant digits.
inline constexpr int kMeasuredDigits = 4;

// x rounded to `digits` significant decimal digits, as the nearest double (which JSON and
// the summaries then print in shortest round-trip form: those digits at most).
inline double significant(double x, int digits) {
  if (!std::isfinite(x) || x == 0) return x;
  char text[40];
  std::snprintf(text, sizeof text, "%.*g", digits, x);
  return std::strtod(text, nullptr);
}

inline double measured(double x) { return significant(x, kMeasuredDigits); }

// A comma and a value of T in the shortest fixed width that round-trips it (%.9g float,
// %.17g double): the trajectory's and events.csv's state columns.
template <class T>
constexpr const char* kRoundTripColumn = sizeof(T) == 4 ? ",%.9g" : ",%.17g";

// Runs f; a library Error it throws (a value the scene gave, checked there) is thrown on
// with the scene file's name in front.
template <class F>
decltype(auto) naming_scene(const std::string& scene_path, F&& f) {
  try {
    return f();
  } catch (const Error& e) {
    throw Error(scene_path + ": " + e.what());
  }
}

// A step an option gives that the run's precision cannot hold (0 or infinite once rounded to
// float) is the option's fault, not the scene file's: said so before the scene's own checks.
inline void check_step_option(const char* option, double dt, Precision p) {
  if (p != Precision::single) return;
  const float rounded = float(dt);
  if (rounded > 0 && std::isfinite(rounded)) return;
  char text[160];
  std::snprintf(text, sizeof text, "%s %g %s in float (give a step float holds, or --precision double)", option, dt,
                rounded == 0 ? "rounds to 0" : "overflows");
  throw Error(text);
}
inline void check_dt_option(const std::optional<double>& dt, Precision p) {
  if (dt) check_step_option("--dt", *dt, p);
}

// A value of the simulation (a step, a time, an energy) to the digits its precision holds:
// a float exactly as short as it round-trips (0.016666668 for 1/60 in float), other values
// of a float run to 9 digits, values of a double run to 15 (the digits every double keeps
// through a decimal text, so 0.1 x 3 shows as 0.3).
inline double in_precision(double x, Precision p) {
  if (!std::isfinite(x)) return x;
  if (p == Precision::single && double(float(x)) == x) {
    char text[40];
    const auto end = std::to_chars(text, text + sizeof text - 1, float(x)).ptr;
    *end = '\0';
    return std::strtod(text, nullptr);
  }
  return significant(x, p == Precision::single ? 9 : 15);
}

// A JSON number: a whole value as an integer (10, not 10.0), any other finite one as it is.
inline nlohmann::ordered_json number(double x) {
  if (!std::isfinite(x)) return nullptr;  // JSON has no NaN or infinity; null, not a number that prints as one
  if (x == std::trunc(x) && std::abs(x) < 0x1p53) return std::int64_t(x);
  return x;
}

}  // namespace kinema::cli
