#include "chart_command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>

#include "kinema/scenes.hpp"
#include "interrupt.hpp"
#include "numbers.hpp"
#include "work_bound.hpp"
#include "plot.hpp"
#include "progress.hpp"

namespace kinema::cli {
namespace fs = std::filesystem;

void make_output_folder(const fs::path& dir) {
  std::error_code error;
  fs::create_directories(dir, error);
  if (error) throw Error("--out " + printable(dir.string()) + ": cannot create the folder (" + error.message() + ")");
}

std::vector<const Method*> pick_methods(const std::vector<std::string>& names, const Scene& scene) {
  std::vector<const Method*> out;
  for (const std::string& n : names) {
    const Method* m = &method_by_name(n);
    if (std::find(out.begin(), out.end(), m) != out.end()) throw Error("--methods names " + printable(n) + " twice");
    out.push_back(m);
  }
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
  // The charts take their methods from --methods (or all): a scene naming an implicit method
  // that its events or rigid bodies refuse is still charted, as kinema run --method would.
  const bool implicit = scene.method != "auto" && method_by_name(scene.method).kind == MethodKind::linearly_implicit;
  const bool refuses = !scene.events.empty() || !scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid);
  if (implicit && refuses) scene.method = "rk4";
  // They run the whole duration: a stop would end kinema run's run elsewhere.
  for (std::size_t e = 0; e < scene.events.size(); ++e) {
    if (scene.events[e].action != EventAction::stop) continue;
    throw Error(path + ": events[" + std::to_string(e) + "] stops kinema run at its crossing; chart and stability run "
                "the whole duration and watch no events (make it \"record\" to chart the run to its end)");
  }
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
  double seconds;  // wall time of the run
  double seconds_per_simulated_second;
  double evaluations;
};

// Wall time of `steps` steps on one thread, stepping only (the minimum of `repeat` runs),
// and the iterations an implicit method's solves took (0 for the others).
struct Timed {
  double seconds;
  std::uint64_t solve_iterations;
};
template <class T>
Timed timed(const Scene& scene, const Method& method, std::uint64_t steps, double duration, int repeat) {
  Timed t{std::numeric_limits<double>::infinity(), 0};
  for (int r = 0; r < repeat; ++r) {
    World<T> world(scene, method, on_calling_thread());
    const auto start = std::chrono::steady_clock::now();
    world.advance(T(duration / double(steps)), steps);
    t.seconds = std::min(t.seconds, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    t.solve_iterations = world.particle_stepper().implicit_stats().iterations;
  }
  return t;
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

// What every method's sweep shares: the scene, the steps and the reference to measure against.
struct Sweep {
  Scene scene;  // the bodies sampled
  double duration;
  std::vector<double> dts;
  Reference ref;
  double epsilon, scale;  // round-off and motion: where a fitted order can be trusted
  int repeat;
};

// The step sizes asked for (default: the scene's dt times 2^-3 .. 2^4, those no longer than
// the duration), smallest first, one per step count.
std::vector<double> step_sizes(const ChartOptions& o, const Scene& full, double duration) {
  std::vector<double> dts = o.dts;
  for (double dt : dts) check_step_option("--dts", dt, full.precision);
  if (dts.empty()) {
    for (int k = -3; k <= 4; ++k) {
      if (full.dt * std::ldexp(1.0, k) <= duration) dts.push_back(full.dt * std::ldexp(1.0, k));
    }
    if (dts.empty()) {  // once a chart of no runs, said to be of errors zero or not finite
      char text[200];
      std::snprintf(text, sizeof text,
                    "the scene's dt (%g s) times 1/8 .. 16 gives no step within the duration (%g s): give --dts "
                    "or a longer --duration",
                    full.dt, duration);
      throw Error(text);
    }
  }
  std::sort(dts.begin(), dts.end());
  dts.erase(std::unique(dts.begin(), dts.end(), [&](double a, double b) {
              return step_count(duration, a) == step_count(duration, b);
            }),
            dts.end());
  return dts;
}

// The sweep's scene, duration and steps; its reference comes after (measure_against_reference).
Sweep plan_sweep(const ChartOptions& o, const Scene& full) {
  const double duration = o.duration.value_or(full.dt * double(full.steps));
  if (!(duration > 0)) throw Error("the duration must be positive (--duration or the scene's dt x steps)");
  Sweep s{sample_bodies(full, o.max_bodies), duration, {}, {}, 0, 0, o.repeat};
  s.dts = step_sizes(o, full, duration);
  return s;
}

// The reference the errors are measured against: 64 times the most steps swept.
void measure_against_reference(Sweep& s) {
  std::uint64_t most_steps = 1;
  for (double dt : s.dts) most_steps = std::max(most_steps, step_count(s.duration, dt));
  s.ref = reference_states(s.scene, s.duration, 64 * most_steps, interrupt_request());
  s.epsilon = s.scene.precision == Precision::single ? 1.2e-7 : 2.2e-16;
  s.scale = motion_scale(s.ref.states);
}

// One run of `m` at about `dt` over the sweep's duration: its error and its cost.
Point measure(const Sweep& s, const Method& m, double dt) {
  const std::uint64_t steps = step_count(s.duration, dt);
  const double h = s.duration / double(steps);
  double error = 0;
  try {
    error = state_error(simulate(s.scene, m, steps, s.duration, interrupt_request()), s.ref.states);
  } catch (const SolveOverflowError&) {  // an implicit method's blow-up: as a state not finite
    const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
    return {&m, h, steps, inf, nan, nan, double(steps) * m.evaluations() * double(s.scene.particles.size())};
  }
  const Timed t = with_precision(
      s.scene.precision, [&]<class T>() { return timed<T>(s.scene, m, steps, s.duration, s.repeat); });
  const std::size_t bodies = s.scene.particles.size() + s.scene.rigid_bodies.size();
  // An implicit solve's iteration (a product over every spring slot) counted as an evaluation.
  const double evaluations = (double(steps) * m.evaluations() + double(t.solve_iterations)) * double(bodies);
  return {&m, h, steps, error, t.seconds, t.seconds / s.duration, evaluations};
}

// What log axes can show.
bool plottable(const Point& p) { return std::isfinite(p.error) && p.error > 0; }

void write_csv_row(std::ofstream& csv, const Point& p, const Reference& ref) {
  // A run an implicit solve's overflow ended was not timed: an empty cell.
  char cost[32] = "";
  if (std::isfinite(p.seconds_per_simulated_second)) std::snprintf(cost, sizeof cost, "%.6g", p.seconds_per_simulated_second);
  char line[512];
  std::snprintf(line, sizeof line, "%s,%d,%.17g,%llu,%.17g,%s,%.17g,%.6g,%s\n",
                std::string(p.method->name).c_str(), p.method->order, p.dt,
                static_cast<unsigned long long>(p.steps), p.error, cost,
                p.evaluations, ref.error, ref.analytic ? "true" : "false");
  csv << line;
}

// A method's sweep: its points, plotted or not, and its key title with the fitted order.
struct Curve {
  const Method* method;
  std::vector<Point> points;
  std::optional<double> order;  // fitted
  std::string legend;

  std::string data_file() const { return "points_" + std::string(method->name) + ".dat"; }
};

std::string legend_of(const Method& m, std::optional<double> order) {
  char legend[128];
  std::snprintf(legend, sizeof legend, order ? "%s (fitted order %.2f)" : "%s (no asymptotic range)",
                std::string(m.name).c_str(), order.value_or(0));
  return legend;
}

// The files of the run so far, by name inside the output folder.
struct Written {
  fs::path dir;
  std::vector<std::string> data, charts;
};

Curve sweep_method(const Sweep& s, const Method& m, std::ofstream& csv, Written& written,
                   const std::function<void()>& tick) {
  Curve curve{&m, {}, {}, {}};
  OutputFile dat(written.dir / curve.data_file());
  written.data.push_back(curve.data_file());
  dat << "# steps dt seconds evaluations error seconds_per_simulated_second\n";
  for (double dt : s.dts) {
    stop_if_interrupted();
    const Point p = measure(s, m, dt);
    curve.points.push_back(p);
    write_csv_row(csv, p, s.ref);
    if (plottable(p)) {
      dat << p.steps << ' ' << p.dt << ' ' << p.seconds << ' '
          << p.evaluations << ' ' << p.error << ' ' << p.seconds_per_simulated_second << '\n';
    }
    tick();
  }
  dat.close();
  curve.order = fitted_order(curve.points, s.epsilon, s.scale, s.ref.error);
  curve.legend = legend_of(m, curve.order);
  return curve;
}

// The axes' shared settings and the key under the plot.
std::string log_chart_head(const std::string& title, const std::string& xlabel,
                           const std::string& ylabel, Frame& frame,
                           const std::vector<std::string>& key_titles) {
  return key_below(frame, key_titles) + "set logscale xy\nset grid\nset format xy '%g'\n" +
         "set title " + gnuplot_quote(title) + "\nset xlabel " + gnuplot_quote(xlabel) +
         "\nset ylabel " + gnuplot_quote(ylabel) + "\n";
}

// One line with points per method: columns `x:y` of its data file, its key title.
std::string method_lines(const std::vector<Curve>& curves, const std::string& columns,
                         const std::vector<std::string>& titles) {
  std::string plot = "plot ";
  for (std::size_t i = 0; i < curves.size(); ++i) {
    plot += std::string(i ? ", \\\n  " : "") + gnuplot_quote(curves[i].data_file()) + " using " +
            columns + " with linespoints lw 2 ps 1.2" + style_of(curves[i].method->name) +
            " title " + gnuplot_quote(titles[i]);
  }
  return plot;
}

// Error and cost of each plotted point, on the work-precision chart's axes.
struct Extent {
  static constexpr double kNone = std::numeric_limits<double>::infinity();
  double min_error = kNone, max_error = 0, min_cost = kNone, max_cost = 0;

  explicit Extent(const std::vector<Curve>& curves) {
    for (const Curve& c : curves) {
      for (const Point& p : c.points) {
        if (!plottable(p) || !(p.seconds_per_simulated_second > 0)) continue;
        min_error = std::min(min_error, p.error), max_error = std::max(max_error, p.error);
        min_cost = std::min(min_cost, p.seconds_per_simulated_second);
        max_cost = std::max(max_cost, p.seconds_per_simulated_second);
      }
    }
  }
};

// Labels h=... at the two ends of each curve, where they fit: labelling every point piles
// them up where methods cluster, and the points between the ends follow the sweep.
std::string end_labels(const std::vector<Curve>& curves, const LogAxis& x, const LogAxis& y,
                       const Frame& frame) {
  std::vector<std::vector<Pixel>> lines;
  std::vector<PointLabel> wanted;
  for (const Curve& c : curves) {
    std::vector<const Point*> shown;
    for (const Point& p : c.points) {
      if (plottable(p) && p.seconds_per_simulated_second > 0) shown.push_back(&p);
    }
    std::vector<Pixel> line;
    for (const Point* p : shown) {
      line.push_back({frame.left + x.fraction(p->error) * frame.width(),
                      frame.top + (1 - y.fraction(p->seconds_per_simulated_second)) * frame.height()});
    }
    lines.push_back(line);
    if (shown.empty()) continue;
    const MethodStyle style = method_style(c.method->name);
    char text[32];
    for (std::size_t k : {std::size_t(0), shown.size() - 1}) {
      std::snprintf(text, sizeof text, "h=%.3g", shown[k]->dt);
      wanted.push_back({line[k], text, style.colour});
      if (shown.size() == 1) break;
    }
  }
  return place_labels(wanted, lines, frame);
}

std::string work_precision_script(const Sweep& s, const std::vector<Curve>& curves) {
  char title[256];
  std::snprintf(title, sizeof title, "Work-precision: %s (%s, %g s simulated, %zu bodies)",
                s.scene.name.c_str(), std::string(precision_name(s.scene.precision)).c_str(),
                s.duration, s.scene.particles.size() + s.scene.rigid_bodies.size());
  std::vector<std::string> names;
  for (const Curve& c : curves) names.emplace_back(c.method->name);
  Frame frame;
  std::string script = log_chart_head(title, "error at the end: max over bodies of |dx| + |dv| (+ orientation, rad)",
                                      "wall time per simulated second, 1 thread (s)", frame, names);
  const Extent e(curves);
  if (e.max_error > 0 && e.max_cost > 0) {  // fixed ranges: the labels are placed against them
    const LogAxis x = LogAxis::around(e.min_error, e.max_error), y = LogAxis::around(e.min_cost, e.max_cost);
    script += "set xrange " + x.range() + "\nset yrange " + y.range() + "\n" + x.tics('x') + y.tics('y') +
              end_labels(curves, x, y, frame);
  }
  return script + method_lines(curves, "5:6", names);
}

std::vector<std::string> legends_of(const std::vector<Curve>& curves) {
  std::vector<std::string> legends;
  for (const Curve& c : curves) legends.push_back(c.legend);
  return legends;
}

std::string error_vs_step_script(const Sweep& s, const std::vector<Curve>& curves) {
  std::vector<std::string> titles = legends_of(curves);
  const bool reference_line = !s.ref.analytic && s.ref.error > 0;
  if (reference_line) titles.push_back("reference error (estimate)");
  Frame frame;
  std::string script = log_chart_head("Error against step size: " + s.scene.name, "step size h (s)",
                                      "error at the end", frame, titles) +
                       method_lines(curves, "2:5", legends_of(curves));
  if (reference_line) {
    char line[128];
    std::snprintf(line, sizeof line, ", %.17g with lines lw 2 dt 3 lc rgb '#999999' title ", s.ref.error);
    script += line + gnuplot_quote(titles.back());
  }
  return script;
}

// Cost as force evaluations: what the method's order buys, whatever its kernel's speed.
std::string error_vs_evaluations_script(const Sweep& s, const std::vector<Curve>& curves) {
  Frame frame;
  return log_chart_head("Error against force evaluations: " + s.scene.name + " (" +
                            std::string(precision_name(s.scene.precision)) + ")",
                        "error at the end", "force evaluations (stages x steps x bodies)", frame,
                        legends_of(curves)) +
         method_lines(curves, "5:4", legends_of(curves));
}

void write_charts(const Sweep& s, const std::vector<Curve>& curves, Written& written) {
  const std::pair<const char*, std::string> charts[] = {
      {"work_precision", work_precision_script(s, curves)},
      {"error_vs_step", error_vs_step_script(s, curves)},
      {"error_vs_evaluations", error_vs_evaluations_script(s, curves)},
  };
  for (const auto& [name, script] : charts) {
    render_chart(written.dir, name, script);
    for (const std::string& file : chart_files(name)) written.charts.push_back(file);
  }
}

void require_plotted(const std::vector<Curve>& curves, const fs::path& dir) {
  for (const Curve& c : curves) {
    if (std::any_of(c.points.begin(), c.points.end(), plottable)) return;
  }
  throw Error("no chart: every error is zero or not finite (the methods are exact on this "
              "scene, or every run blew up); the values are in " +
              (dir / "work_precision.csv").string());
}

void print_summary(const Sweep& s, const std::vector<Curve>& curves, const Written& written) {
  std::printf("kinema chart: %s, %zu methods x %zu step sizes, reference %s\n",
              printable(s.scene.name).c_str(), curves.size(), s.dts.size(),
              s.ref.analytic ? "analytic" : ("rk4 double, " + std::to_string(s.ref.steps) + " steps").c_str());
  for (const Curve& c : curves) std::printf("  %s\n", c.legend.c_str());
  std::printf("wrote in %s:\n", printable(written.dir.string()).c_str());
  for (const auto* group : {&written.data, &written.charts}) {
    std::string line;
    for (const std::string& file : *group) {
      if (!line.empty() && line.size() + file.size() > 96) std::printf("%s\n", line.c_str()), line.clear();
      line += "  " + printable(file);
    }
    std::printf("%s\n", line.c_str());
  }
}

}  // namespace

// The sweep's force evaluations (every method at every step size, `repeat` times) and the
// reference's (rk4 at 64 and 32 times the most steps, in double: twice the cost).
double planned_evaluations(const Sweep& s, const std::vector<const Method*>& methods) {
  double evaluations = 0;
  std::uint64_t most_steps = 1;
  for (double dt : s.dts) {
    const std::uint64_t steps = step_count(s.duration, dt);
    most_steps = std::max(most_steps, steps);
    for (const Method* m : methods) evaluations += double(s.repeat) * double(steps) * m->evaluations();
  }
  const bool analytic = analytic_states(s.scene, s.duration).has_value();
  return evaluations + (analytic ? 0 : 2 * 96 * double(most_steps) * rk4.evaluations());
}

int chart_scene(const ChartOptions& o) {
  const Scene full = load_checked(o.scene_path, o.precision);
  Sweep sweep = plan_sweep(o, full);
  const std::vector<const Method*> methods = pick_methods(o.methods, full);
  check_work(o.scene_path, "the chart", planned_evaluations(sweep, methods), sweep.scene,
             "give fewer or longer --dts, a shorter --duration or fewer --methods");
  measure_against_reference(sweep);
  make_output_folder(o.out);
  Written written{o.out, {"work_precision.csv", "orders.csv"}, {}};
  OutputFile csv(written.dir / "work_precision.csv");
  csv << "method,order,dt,steps,error,seconds_per_simulated_second,force_evaluations,"
         "reference_error,analytic_reference\n";
  OutputFile orders(written.dir / "orders.csv");
  orders << "method,nominal_order,fitted_order\n";
  Progress progress("kinema chart", o.quiet);
  std::size_t done = 0;
  const auto tick = [&] { progress.update(double(++done) / double(methods.size() * sweep.dts.size())); };
  std::vector<Curve> curves;
  for (const Method* m : methods) {
    curves.push_back(sweep_method(sweep, *m, csv, written, tick));
    const std::optional<double> order = curves.back().order;
    orders << m->name << ',' << m->order << ',' << (order ? std::to_string(*order) : "") << '\n';
  }
  progress.finish();
  csv.close();
  orders.close();
  require_plotted(curves, written.dir);
  write_charts(sweep, curves, written);
  if (!o.quiet) print_summary(sweep, curves, written);
  return 0;
}

}  // namespace kinema::cli
