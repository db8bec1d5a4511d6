#include "chart_command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>

#include "kinema/scenes.hpp"
#include "interrupt.hpp"
#include "plot.hpp"
#include "progress.hpp"

namespace kinema::cli {
namespace fs = std::filesystem;

std::vector<const Method*> pick_methods(const std::vector<std::string>& names, const Scene& scene) {
  std::vector<const Method*> out;
  for (const std::string& n : names) out.push_back(&method_by_name(n));
  if (out.empty()) {
    out.assign(builtin_methods.begin(), builtin_methods.end());
    // Rigid bodies take the fused kernels only: the built-in methods.
    const bool rigid = !scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid);
    if (!rigid) out.insert(out.end(), staged_methods.begin(), staged_methods.end());
  }
  return out;
}

std::uint64_t step_count(double duration, double dt) {
  const double steps = std::round(duration / dt);
  const char* problem = steps > 4294967296.0 ? "takes more than 2^32 steps"
                        : steps < 1          ? "is longer than the duration"
                                             : nullptr;
  if (problem != nullptr) {
    char text[160];
    std::snprintf(text, sizeof text, "a step of %g s over %g s %s", dt, duration, problem);
    throw Error(text);
  }
  return std::uint64_t(steps);
}

Scene load_checked(const std::string& path, std::optional<Precision> precision) {
  Scene scene = load_scene(path);
  if (precision) scene.precision = *precision;
  try {
    with_precision(scene.precision, [&]<class T>() { check_scene<T>(scene); });
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  return scene;
}

double least_squares_slope(const std::vector<double>& x, const std::vector<double>& y) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = double(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    sx += x[i], sy += y[i], sxx += x[i] * x[i], sxy += x[i] * y[i];
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

namespace {

struct Point {
  const Method* method;
  double dt;
  std::uint64_t steps;
  double error;
  double seconds_per_simulated_second;
  double evaluations;
};

// Wall time of `steps` steps on one thread, stepping only: the minimum of `repeat` runs.
template <class T>
double timed(const Scene& scene, const Method& method, std::uint64_t steps, double duration,
             int repeat) {
  double best = std::numeric_limits<double>::infinity();
  for (int r = 0; r < repeat; ++r) {
    World<T> world(scene, method, on_calling_thread());
    const auto start = std::chrono::steady_clock::now();
    world.advance(T(duration / double(steps)), steps);
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  return best;
}

// The order from the three smallest steps whose error stands clear of round-off (ten times
// steps x epsilon x scale, and a hundred times the reference's own error) and is still
// smaller than the motion itself: the asymptotic range, where error ~ C h^p.
std::optional<double> fitted_order(const std::vector<Point>& points, double epsilon, double scale,
                                   double reference_error) {
  std::vector<const Point*> usable;
  for (const Point& p : points) {
    const double floor = std::max(10 * double(p.steps) * epsilon * scale, 100 * reference_error);
    if (p.error > floor && p.error < 0.5 * scale) usable.push_back(&p);
  }
  std::sort(usable.begin(), usable.end(), [](auto* a, auto* b) { return a->dt < b->dt; });
  if (usable.size() > 3) usable.resize(3);
  if (usable.size() < 2) return std::nullopt;
  std::vector<double> x, y;
  for (const Point* p : usable) x.push_back(std::log(p->dt)), y.push_back(std::log(p->error));
  return least_squares_slope(x, y);
}

double motion_scale(const BodyStates& s) {
  double scale = 1;
  for (const auto& x : s.positions) scale = std::max(scale, std::hypot(x[0], x[1], x[2]));
  return scale;
}

void write_charts(const fs::path& dir, const Scene& scene, const std::vector<const Method*>& methods,
                  const std::vector<std::string>& legends, const Reference& ref, double duration) {
  std::string wp = "set logscale xy\nset grid\nset key outside right\n";
  char title[256];
  std::snprintf(title, sizeof title, "Work-precision: %s (%s, %g s simulated, %zu bodies)",
                scene.name.c_str(), std::string(precision_name(scene.precision)).c_str(), duration,
                scene.particles.size() + scene.rigid_bodies.size());
  wp += "set title " + gnuplot_quote(title) + "\n";
  wp += "set xlabel 'error at the end: max over bodies of |dx| + |dv| (+ orientation, rad)'\n";
  wp += "set ylabel 'wall time per simulated second, 1 thread (s)'\n";
  wp += "plot ";
  // Cost as force evaluations: what the method's order buys, whatever its kernel's speed.
  std::string fe = "set logscale xy\nset grid\nset key outside right\n";
  fe += "set title " + gnuplot_quote("Error against force evaluations: " + scene.name + " (" +
                                      std::string(precision_name(scene.precision)) + ")") + "\n";
  fe += "set xlabel 'error at the end'\nset ylabel 'force evaluations (stages x steps x bodies)'\nplot ";
  std::string ev = "set logscale xy\nset grid\nset key outside right\n";
  ev += "set title " + gnuplot_quote("Error against step size: " + scene.name) + "\n";
  ev += "set xlabel 'step size h (s)'\nset ylabel 'error at the end'\nplot ";
  for (std::size_t i = 0; i < methods.size(); ++i) {
    const std::string data = gnuplot_quote("points_" + std::string(methods[i]->name) + ".dat");
    const std::string sep = i + 1 < methods.size() ? ", \\\n  " : "";
    const std::string lc = " lc " + std::to_string(i + 1);
    wp += data + " using 5:6 with linespoints pt 7" + lc + " title " +
          gnuplot_quote(std::string(methods[i]->name)) + ", " + data +
          " using 5:6:(sprintf('h=%.3g', $2)) with labels offset 0.6,0.6 font ',8' tc lt " +
          std::to_string(i + 1) + " notitle" + sep;
    ev += data + " using 2:5 with linespoints pt 7" + lc + " title " + gnuplot_quote(legends[i]) + sep;
    fe += data + " using 5:4 with linespoints pt 7" + lc + " title " + gnuplot_quote(legends[i]) + sep;
  }
  if (!ref.analytic && ref.error > 0) {
    ev += ", " + std::to_string(ref.error) + " with lines dt 2 lc 'gray' title 'reference error (estimate)'";
  }
  render_chart(dir, "work_precision", wp);
  render_chart(dir, "error_vs_step", ev);
  render_chart(dir, "error_vs_evaluations", fe);
}

}  // namespace

int chart_scene(const ChartOptions& o) {
  const Scene full = load_checked(o.scene_path, o.precision);
  const Scene scene = sample_bodies(full, o.max_bodies);
  const double duration = o.duration.value_or(full.dt * double(full.steps));
  if (!(duration > 0)) throw Error("the duration must be positive (--duration or the scene's dt x steps)");
  std::vector<double> dts = o.dts;
  if (dts.empty()) {
    for (int k = -3; k <= 4; ++k) dts.push_back(full.dt * std::ldexp(1.0, k));
  }
  const std::vector<const Method*> methods = pick_methods(o.methods, full);
  std::sort(dts.begin(), dts.end());
  dts.erase(std::unique(dts.begin(), dts.end(), [&](double a, double b) {
              return step_count(duration, a) == step_count(duration, b);
            }),
            dts.end());
  std::uint64_t most_steps = 1;
  for (double dt : dts) most_steps = std::max(most_steps, step_count(duration, dt));
  const Reference ref = reference_states(scene, duration, 64 * most_steps);

  fs::create_directories(o.out);
  OutputFile csv(fs::path(o.out) / "work_precision.csv");
  csv << "method,order,dt,steps,error,seconds_per_simulated_second,force_evaluations,"
         "reference_error,analytic_reference\n";
  const double eps = scene.precision == Precision::single ? 1.2e-7 : 2.2e-16;
  const double scale = motion_scale(ref.states);
  Progress progress("kinema chart", o.quiet);
  std::vector<std::string> legends;
  OutputFile orders(fs::path(o.out) / "orders.csv");
  orders << "method,nominal_order,fitted_order\n";
  std::size_t done = 0, plotted = 0;
  for (const Method* m : methods) {
    std::vector<Point> points;
    OutputFile dat(fs::path(o.out) / ("points_" + std::string(m->name) + ".dat"));
    dat << "# steps dt seconds evaluations error seconds_per_simulated_second\n";
    for (double dt : dts) {
      stop_if_interrupted();
      const std::uint64_t steps = step_count(duration, dt);
      const double h = duration / double(steps);
      const double error = state_error(simulate(scene, *m, steps, duration), ref.states);
      const double seconds = with_precision(
          scene.precision, [&]<class T>() { return timed<T>(scene, *m, steps, duration, o.repeat); });
      const std::size_t bodies = scene.particles.size() + scene.rigid_bodies.size();
      const double evaluations = double(steps) * m->evaluations() * double(bodies);
      points.push_back({m, h, steps, error, seconds / duration, evaluations});
      char line[512];
      std::snprintf(line, sizeof line, "%s,%d,%.17g,%llu,%.17g,%.6g,%.17g,%.6g,%s\n",
                    std::string(m->name).c_str(), m->order, h, static_cast<unsigned long long>(steps),
                    error, seconds / duration, evaluations, ref.error, ref.analytic ? "true" : "false");
      csv << line;
      if (std::isfinite(error) && error > 0) {  // what log axes can show
        ++plotted;
        dat << steps << ' ' << h << ' ' << seconds << ' ' << evaluations << ' ' << error << ' '
            << seconds / duration << '\n';
      }
      progress.update(double(++done) / double(methods.size() * dts.size()));
    }
    const auto order = fitted_order(points, eps, scale, ref.error);
    char legend[128];
    std::snprintf(legend, sizeof legend, order ? "%s (fitted order %.2f)" : "%s (no asymptotic range)",
                  std::string(m->name).c_str(), order.value_or(0));
    legends.push_back(legend);
    orders << m->name << ',' << m->order << ',' << (order ? std::to_string(*order) : "") << '\n';
    dat.close();
  }
  progress.finish();
  csv.close();
  orders.close();
  if (plotted == 0) {
    throw Error("no chart: every error is zero or not finite (the methods are exact on this "
                "scene, or every run blew up); the values are in " +
                (fs::path(o.out) / "work_precision.csv").string());
  }
  write_charts(o.out, scene, methods, legends, ref, duration);
  if (!o.quiet) {
    std::printf("kinema chart: %s, %zu methods x %zu step sizes, reference %s\n", printable(scene.name).c_str(),
                methods.size(), dts.size(),
                ref.analytic ? "analytic" : ("rk4 double, " + std::to_string(ref.steps) + " steps").c_str());
    for (const std::string& l : legends) std::printf("  %s\n", l.c_str());
    std::printf("wrote %s/{work_precision,orders}.csv and {work_precision,error_vs_step}.{svg,png}\n",
                printable(o.out).c_str());
  }
  return 0;
}

}  // namespace kinema::cli
