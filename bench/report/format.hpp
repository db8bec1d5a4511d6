#pragma once
// One figure of a run and the cells of the report's tables: "-" wherever a figure is missing
// or not finite, so that a missing run never prints a made-up ratio.
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

namespace kinema::bench::report {

struct Figure {
  double median = 0;  // of the counter, over repetitions
  double cv = 0;      // coefficient of variation, 0 without repetitions
  double max = 0;     // the best repetition, where the run computed it (the machine's limits)
};

inline std::string cell(std::optional<double> x, const char* format) {
  if (!x || !std::isfinite(*x)) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, *x);
  return buf;
}

inline std::optional<double> percent(std::optional<double> x) {
  if (!x) return std::nullopt;
  return 100 * *x;
}

inline std::optional<double> median(std::optional<Figure> f) {
  if (!f) return std::nullopt;
  return f->median;
}

inline std::optional<double> ratio(std::optional<Figure> a, std::optional<Figure> b) {
  if (!a || !b) return std::nullopt;
  return a->median / b->median;
}

}  // namespace kinema::bench::report
