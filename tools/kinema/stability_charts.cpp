#include "stability_charts.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <tuple>

#include "plot.hpp"

namespace kinema::cli {
namespace fs = std::filesystem;

namespace {

using Complex = std::complex<double>;

std::vector<std::string> names_of(const std::vector<const Method*>& methods) {
  std::vector<std::string> names;
  for (const Method* m : methods) names.emplace_back(m->name);
  return names;
}

// One curve per method from PREFIXMETHOD.dat, in the method's style.
std::string method_curves(const std::vector<std::string>& methods, const std::string& prefix,
                          const std::string& options) {
  std::string plot = "plot ";
  for (std::size_t i = 0; i < methods.size(); ++i) {
    plot += std::string(i ? ", \\\n  " : "") + gnuplot_quote(prefix + methods[i] + ".dat") +
            " with lines " + options + style_of(methods[i], false) + " title " + gnuplot_quote(methods[i]);
  }
  return plot + "\n";
}

}  // namespace

void render_energy_chart(const fs::path& dir, const std::string& scene, double dt,
                         const std::vector<const Method*>& methods) {
  const std::vector<std::string> names = names_of(methods);
  char title[400];
  std::snprintf(title, sizeof title, "Energy error: %s, h = %.6g", scene.c_str(), dt);
  Frame frame;
  render_chart(dir, "energy",
               key_below(frame, names) + "set logscale y\nset grid\nset format y '%.0e'\n" +
                   // No minor tics: across the tens of decades of a blow-up they crowd into blots.
                   "set mytics 1\n" +
                   "set title " + gnuplot_quote(title) +
                   "\nset xlabel 't (s)'\nset ylabel '|E - E_0| / |E_0|'\n" +
                   method_curves(names, "energy_", "lw 2"));
}

void render_trajectory_chart(const fs::path& dir, const std::string& scene,
                             const std::vector<const Method*>& methods) {
  // At equal scales the plot is about square: the key goes beside it, in the width it leaves.
  render_chart(dir, "trajectory",
               "set grid\nset size ratio -1\nset key outside right top vertical samplen 3\n"
               "set title " + gnuplot_quote("Trajectory of body 0: " + scene) +
                   "\nset xlabel 'x'\nset ylabel 'y'\n" + method_curves(names_of(methods), "path_", "lw 2"));
}

namespace {

// Orders each phi's roots to continue the nearest roots of the phi before, so that each
// position in the rows follows one branch of the boundary; the last row returns to phi = 0.
std::vector<std::vector<Complex>> trace_branches(const std::vector<std::vector<Complex>>& roots) {
  std::vector<std::vector<Complex>> rows{roots.front()};
  for (std::size_t k = 1; k <= roots.size(); ++k) {
    const std::vector<Complex>& before = rows.back();
    const std::vector<Complex>& next = roots[k % roots.size()];
    std::vector<std::tuple<double, std::size_t, std::size_t>> pairs;
    for (std::size_t i = 0; i < before.size(); ++i) {
      for (std::size_t j = 0; j < next.size(); ++j) pairs.emplace_back(std::abs(before[i] - next[j]), i, j);
    }
    std::sort(pairs.begin(), pairs.end());
    std::vector<Complex> row(before.size());
    std::vector<bool> row_set(before.size()), used(next.size());
    for (const auto& [distance, i, j] : pairs) {
      if (row_set[i] || used[j]) continue;
      row[i] = next[j], row_set[i] = used[j] = true;
    }
    rows.push_back(row);
  }
  return rows;
}

// Beyond this |z| a boundary point is off the chart: the main regions lie well inside, and a
// far, tiny island (rk6 has one near 7.86) would shrink them to a corner.
constexpr double kChartReach = 6;

void write_boundary(const fs::path& file, const std::vector<std::vector<Complex>>& rows) {
  OutputFile dat(file);
  for (std::size_t branch = 0; branch < rows.front().size(); ++branch) {
    for (const auto& row : rows) dat << row[branch].real() << ' ' << row[branch].imag() << '\n';
    dat << '\n';
  }
  dat.close();
}

// The earlier method whose region is the same (same polynomial), or null.
const RegionBoundary* same_region(const std::vector<RegionBoundary>& regions, std::size_t i) {
  for (std::size_t j = 0; j < i; ++j) {
    const auto& a = regions[i].polynomial;
    const auto& b = regions[j].polynomial;
    if (a.size() != b.size()) continue;
    bool same = true;
    for (std::size_t k = 0; k < a.size(); ++k) same = same && std::abs(a[k] - b[k]) <= 1e-12 * std::abs(b[k]);
    if (same) return &regions[j];
  }
  return nullptr;
}

// The chart's window at equal scales: every boundary point within reach, and on the right of
// them room for the key (`key_width` x `key_height` pixels, centred on the real axis), at the
// frame's aspect.
struct Window {
  double x_lo, x_hi, y_half;
  std::string far_note;  // what lies beyond reach
};

Window window_for(const std::vector<RegionBoundary>& regions, const Frame& frame, double key_width,
                  double key_height) {
  std::vector<Complex> near;
  std::string far;
  for (const RegionBoundary& r : regions) {
    double far_re = 0;
    std::size_t far_count = 0;
    for (const auto& row : r.roots) {
      for (const Complex& z : row) {
        if (std::abs(z) <= kChartReach) near.push_back(z);
        else far_re += z.real(), ++far_count;
      }
    }
    if (far_count > 0) {
      char note[160];
      std::snprintf(note, sizeof note, "%s%s also has a small region near Re = %.3g, off the chart",
                    far.empty() ? "" : "; ", r.method.c_str(), far_re / double(far_count));
      far += note;
    }
  }
  double left = 0, top = 0;
  for (const Complex& z : near) left = std::min(left, z.real()), top = std::max(top, std::abs(z.imag()));
  const double pad = 0.3, x_lo = left - pad;
  // Pixels per unit: the regions' height fills the frame, unless the key then lacks room
  // beside the boundary points level with it; a smaller unit makes the key's band taller.
  double unit = frame.height() / (2 * (top + pad));
  for (int pass = 0; pass < 4; ++pass) {
    const double band = key_height / 2 / unit + pad;
    double edge = 0;
    for (const Complex& z : near) {
      if (std::abs(z.imag()) <= band) edge = std::max(edge, z.real());
    }
    unit = std::min(unit, (frame.width() - key_width - 20) / (edge + pad - x_lo));
  }
  return {x_lo, x_lo + frame.width() / unit, frame.height() / (2 * unit), far};
}

constexpr const char* kLimitTitle = "x: measured limit of x' = -lambda x";

// "heun = midpoint, limit 2": the method, the earlier one with the same region, the limit.
std::string region_title(const std::vector<RegionBoundary>& regions, std::size_t i) {
  const RegionBoundary* twin = same_region(regions, i);
  char title[160];
  std::snprintf(title, sizeof title, "%s%s%s, limit %.4g", regions[i].method.c_str(), twin ? " = " : "",
                twin ? twin->method.c_str() : "", regions[i].measured_limit);
  return title;
}

}  // namespace

void render_region_chart(const fs::path& dir, const std::vector<RegionBoundary>& regions) {
  // A tall canvas, the key inside on the right: the regions fill the chart at equal scales.
  Frame frame{{820, 760}, 70, 25, 45, 60};
  std::vector<std::string> titles;
  for (std::size_t i = 0; i < regions.size(); ++i) titles.push_back(region_title(regions, i));
  titles.push_back(kLimitTitle);
  const Window w = window_for(regions, frame, key_column_width(titles), key_height(titles.size() + 1));
  char ranges[160];
  std::snprintf(ranges, sizeof ranges, "set xrange [%.4f:%.4f]\nset yrange [%.4f:%.4f]\n", w.x_lo, w.x_hi,
                -w.y_half, w.y_half);
  std::string script = frame.margins() + ranges +
                       "set grid\nset key at graph 0.98,0.5 right center vertical box opaque samplen 3\n"
                       "set title 'Stability regions |R(h lambda)| <= 1 of the explicit Runge-Kutta methods'\n"
                       "set xlabel 'Re(h lambda)'\nset ylabel 'Im(h lambda)'\n";
  if (!w.far_note.empty()) {
    script += "set label " + gnuplot_quote(w.far_note) + " at graph 0.98,0.03 right font ',11'\n";
  }
  std::string plot = "plot ";
  for (std::size_t i = 0; i < regions.size(); ++i) {
    const RegionBoundary& r = regions[i];
    write_boundary(dir / ("region_" + r.method + ".dat"), trace_branches(r.roots));
    OutputFile mark(dir / ("threshold_" + r.method + ".dat"));
    mark << -r.measured_limit << " 0\n";
    mark.close();
    // A region drawn again over the same one is thinner, so both show.
    const bool twin = same_region(regions, i) != nullptr;
    plot += std::string(i ? ", \\\n  " : "") + gnuplot_quote("region_" + r.method + ".dat") +
            " with lines lw " + (twin ? "2" : "3") + style_of(r.method, false) + " title " +
            gnuplot_quote(titles[i]) +
            ", " + gnuplot_quote("threshold_" + r.method + ".dat") + " with points pt 2 ps 2 lw 2" +
            style_of(r.method, false) + " notitle";
  }
  plot += ", \\\n  keyentry with points pt 2 ps 2 lw 2 lc rgb '#000000' title " +
          gnuplot_quote(kLimitTitle) + "\n";
  render_chart(dir, "stability_region", script + plot, frame.canvas);
}

void render_step_limits(const fs::path& dir, const std::vector<StepLimit>& limits, double stiffness,
                        double dt) {
  OutputFile dat(dir / "step_limits.dat");
  double lo = dt, hi = dt;
  for (const StepLimit& l : limits) {
    // Zero and infinite steps have no place on a log scale: drawn at the axis' ends.
    const double predicted = std::clamp(l.predicted, dt / 1e3, dt * 1e3);
    const double measured = std::clamp(l.measured, dt / 1e3, dt * 1e3);
    dat << '"' << l.method << "\" " << predicted << ' ' << measured << '\n';
    lo = std::min({lo, predicted, measured}), hi = std::max({hi, predicted, measured});
  }
  dat.close();
  // The range holds dt too, away from the frame: the dt line must not lie on an axis.
  const LogAxis y = LogAxis::around(lo, hi);
  char head[400];
  std::snprintf(head, sizeof head,
                "set logscale y\nset grid\nset xtics rotate by -30\nset yrange %s\n%sset xrange [-0.5:%.1f]\n"
                "set title 'Largest stable step: predicted (|lambda| = %.4g /s at the start) and measured'\n"
                "set ylabel 'h (s)'\n",
                y.range().c_str(), y.tics('y').c_str(), double(limits.size()) - 0.5, stiffness);
  const char* const titles[] = {"predicted", "measured blow-up", "the scene's dt"};
  Frame frame;
  const std::string key = key_below(frame, {std::begin(titles), std::end(titles)}, 110);
  char dt_line[160];
  std::snprintf(dt_line, sizeof dt_line, ", %.17g with lines lw 2 dt 2 lc rgb '#555555' title ", dt);
  render_chart(dir, "step_limits",
               key + head +
                   "plot 'step_limits.dat' using 0:2:xtic(1) with points pt 7 ps 1.5 lc rgb '#000000' title "
                   "'predicted', '' using 0:3 with points pt 6 ps 2.2 lw 2 lc rgb '#0072B2' title "
                   "'measured blow-up'" + dt_line + "'the scene''s dt'");
}

}  // namespace kinema::cli
