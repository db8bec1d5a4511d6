// `kinema stability`: energy error against time per method, the trajectories of planar
// motions, and the stability regions of the explicit Runge-Kutta methods with the measured
// limits of the test equation x' = -lambda x marked.
#include <algorithm>
#include <cmath>
#include <limits>
#include <complex>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <variant>

#include "chart_command.hpp"
#include "kinema/scenes.hpp"
#include "kinema/stability.hpp"
#include "interrupt.hpp"
#include "work_bound.hpp"
#include "plot.hpp"
#include "progress.hpp"
#include "stability_charts.hpp"

namespace kinema::cli {
namespace fs = std::filesystem;

namespace {

using Complex = std::complex<double>;

// R(z) = sum_k c_k z^k with c_0 = 1, c_k = b^T A^(k-1) 1: the growth factor of an explicit
// Runge-Kutta method on x' = lambda x, z = h lambda.
std::vector<double> stability_polynomial(const ButcherTableau& t) {
  std::vector<double> c{1};
  std::array<double, kMaxStages> v{};
  for (int i = 0; i < t.stages; ++i) v[i] = 1;  // A^0 1
  for (int k = 1; k <= t.stages; ++k) {
    double ck = 0;
    for (int i = 0; i < t.stages; ++i) ck += t.b[i] * v[i];
    c.push_back(ck);
    std::array<double, kMaxStages> next{};
    for (int i = 0; i < t.stages; ++i) {
      for (int j = 0; j < t.stages; ++j) next[i] += t.a[i][j] * v[j];
    }
    v = next;
  }
  while (c.size() > 1 && c.back() == 0) c.pop_back();
  return c;
}

// Roots of sum_k p_k z^k (Durand-Kerner), for the boundary locus R(z) = e^(i phi).
std::vector<Complex> roots(const std::vector<Complex>& p) {
  const int n = int(p.size()) - 1;
  std::vector<Complex> z(n);
  for (int i = 0; i < n; ++i) z[i] = std::pow(Complex(0.4, 0.9), i);
  for (int iter = 0; iter < 500; ++iter) {
    for (int i = 0; i < n; ++i) {
      Complex value = p[n], denom = p[n];
      for (int k = n - 1; k >= 0; --k) value = value * z[i] + p[k];
      for (int j = 0; j < n; ++j) {
        if (j != i) denom *= z[i] - z[j];
      }
      z[i] -= value / denom;
    }
  }
  return z;
}

// The largest h lambda for which linear drag alone (v' = -lambda v) does not grow, by
// bisection on runs of the library itself.
double measured_threshold(const Method& m) {
  auto stable = [&](double z) {
    ParticleSet<double> b;
    b.add({0, 0, 0}, {1, 0, 0}, 1);
    ForceModel<double> f;
    f.add(LinearDrag{1});
    Stepper<double>(f, m, on_calling_thread()).advance(b, z, 4000);
    return std::isfinite(b.vx()[0]) && std::abs(b.vx()[0]) <= 1;
  };
  double lo = 0.5, hi = 4;
  while (hi - lo > 1e-6) (stable(0.5 * (lo + hi)) ? lo : hi) = 0.5 * (lo + hi);
  return lo;
}

void write_regions(const fs::path& dir, const std::vector<const Method*>& methods) {
  OutputFile csv(dir / "stability_region.csv"), limits(dir / "thresholds.csv");
  csv << "method,re,im\n";
  limits << "method,measured_threshold\n";
  std::vector<RegionBoundary> regions;
  for (const Method* m : methods) {
    if (m->kind != MethodKind::runge_kutta) continue;
    const std::vector<double> c = stability_polynomial(m->tableau);
    stop_if_interrupted();
    RegionBoundary region{std::string(m->name), c, {}, 0};
    for (int k = 0; k < 240; ++k) {
      std::vector<Complex> p(c.begin(), c.end());
      p[0] -= std::polar(1.0, 2 * M_PI * k / 240);
      region.roots.push_back(roots(p));
      for (const Complex& z : region.roots.back()) csv << m->name << ',' << z.real() << ',' << z.imag() << '\n';
    }
    region.measured_limit = measured_threshold(*m);
    limits << m->name << ',' << region.measured_limit << '\n';
    regions.push_back(std::move(region));
  }
  csv.close();
  limits.close();
  if (!regions.empty()) render_region_chart(dir, regions);
}

// Returns how many points of the energy error it wrote for the chart.
template <class T>
std::size_t record(const Scene& scene, const Method& m, double dt, std::uint64_t steps,
                   std::ofstream& energy_csv, std::ofstream& path_csv, std::ofstream& energy_dat,
                   std::ofstream& path_dat, double& max_z) {
  World<T> world(scene, m, on_calling_thread());
  const double e0 = world.total_energy();
  // N-body potential energy costs a pair sum of its own: fewer points there.
  const std::uint64_t points = scene.nbody ? 100 : 2000;
  const std::uint64_t every = std::max<std::uint64_t>(1, steps / points);
  const ParticleSet<T>& centres = world.particles.size() ? world.particles : world.rigid.centers();
  std::size_t plotted = 0;
  for (std::uint64_t k = 0; k <= steps; k += every) {
    const double t = double(k) * dt, e = world.total_energy(), rel = (e - e0) / std::abs(e0);
    const auto x = centres.position(0);
    energy_csv << m.name << ',' << t << ',' << e << ',';
    if (e0 != 0) energy_csv << rel;  // no relative error from an energy of 0: an empty cell
    energy_csv << '\n';
    path_csv << m.name << ',' << t << ',' << x[0] << ',' << x[1] << ',' << x[2] << '\n';
    if (std::isfinite(rel)) energy_dat << t << ' ' << std::max(std::abs(rel), 1e-17) << '\n', ++plotted;
    path_dat << x[0] << ' ' << x[1] << '\n';
    max_z = std::max(max_z, double(std::abs(x[2])));
    const std::uint64_t n = std::min(every, steps - std::min(steps, k));
    if (n == 0) break;
    try {
      world.advance(T(dt), n, interrupt_request());
    } catch (const SolveOverflowError&) {
      break;  // an implicit method's blow-up: its curve ends, as one that is not finite leaves the chart
    }
    stop_if_interrupted();  // the steps it did not take
  }
  return plotted;
}

// For a spring network: the bound on its fastest mode and the steps it allows the methods
// that are stable on the imaginary axis, into spring_limit.csv and one printed line.
std::string spring_limits(const Scene& scene, const fs::path& dir) {
  if (scene.springs.empty()) return "";
  const ForceModel<double> forces = make_forces<double>(scene);
  const double omega = spring_frequency_bound(make_particles<double>(scene), forces.springs());
  OutputFile csv(dir / "spring_limit.csv");
  csv << "omega_bound,method,largest_stable_h\n";
  for (const Method* m : {&symplectic_euler, &velocity_verlet, &rk4}) {
    csv << omega << ',' << m->name << ',' << stability_limits(*m).imaginary_axis / omega << '\n';
  }
  csv.close();
  char line[256];
  std::snprintf(line, sizeof line,
                "springs: fastest mode omega <= %.4g rad/s; undamped, velocity_verlet and "
                "symplectic_euler hold for h < %.4g, rk4 for h < %.4g, euler never\n",
                omega, stability_limits(velocity_verlet).imaginary_axis / omega,
                stability_limits(rk4).imaginary_axis / omega);
  return line;
}

// Does a run of `m` at step h over the duration stay bounded: every value finite and the
// energy within |E0| of where it started?
template <class T>
bool holds(const Scene& scene, const Method& m, double h, double duration) {
  World<T> world(scene, m, on_calling_thread());
  const double e0 = world.total_energy();
  try {
    world.advance(T(h), step_count(duration, h), interrupt_request());
  } catch (const SolveOverflowError&) {
    return false;  // an implicit method's blow-up
  }
  stop_if_interrupted();  // the steps it did not take
  return world.finite() && std::abs(world.total_energy() - e0) <= std::max(std::abs(e0), 1e-300);
}

// The largest step that holds, by bisection on a log scale around `guess` (to 0.5%); 0 or
// infinity when even guess / 512 fails or guess * 512 holds. Capped: no step under the
// duration failed (a step is never longer than the run), so the limit is at least `step`.
struct MeasuredStep {
  double step;
  bool capped;
};

template <class T>
MeasuredStep measured_step(const Scene& scene, const Method& m, double guess, double duration) {
  // Not centred on the guess: its first midpoint is not the guess. Below the duration: a
  // step longer than the run fails for that alone.
  double lo = std::min(guess / 7, duration / 1.01), hi = std::max(guess * 9, lo * 1.5);
  const auto ok = [&](double h) { return h < duration && holds<T>(scene, m, h, duration); };
  for (int k = 0; k < 3 && !ok(lo); ++k) hi = lo, lo /= 8;
  if (!ok(lo)) return {0, false};
  for (int k = 0; k < 3 && ok(hi); ++k) lo = hi, hi *= 8;
  if (ok(hi)) return {std::numeric_limits<double>::infinity(), false};
  while (hi / lo > 1.005) {
    stop_if_interrupted();
    // The geometric mean; from the square roots where the product leaves double's range.
    const double product = lo * hi;
    const double mid = product >= std::numeric_limits<double>::min() && std::isfinite(product) ? std::sqrt(product)
                                                                                               : std::sqrt(lo) * std::sqrt(hi);
    (ok(mid) ? lo : hi) = mid;
  }
  return {lo, hi >= duration};
}

// One method's largest stable step on the scene: predicted from the stiffness at the start,
// and measured over the duration.
struct MethodLimit {
  const Method* method;
  StiffnessEstimate estimate;  // what `predicted` comes from
  double predicted, measured;
  bool capped;  // every step under the duration held: the limit is at least `measured`
  // The measured limit well below the prediction: the scene broke the linear bound.
  bool broken() const { return !capped && std::isfinite(predicted) && predicted > 0 && measured < 0.8 * predicted; }
};

// `e`: the scene's estimate; `explicit_e`: its forces but the springs', which implicit methods
// step explicitly (ImplicitMode).
std::vector<MethodLimit> measure_limits(const Scene& scene, const std::vector<const Method*>& methods,
                                      const StiffnessEstimate& e, const StiffnessEstimate& explicit_e, double dt,
                                      double duration) {
  std::vector<MethodLimit> limits;
  for (const Method* m : methods) {
    stop_if_interrupted();
    const bool implicit = m->kind == MethodKind::linearly_implicit;
    const StiffnessEstimate& used = implicit ? explicit_e : e;
    const double predicted = largest_stable_step(*m, used, ImplicitMode::explicit_forces);
    const double guess = predicted > 0 && std::isfinite(predicted) ? predicted : dt;
    const MeasuredStep measured = with_precision(scene.precision, [&]<class T>() {
      return measured_step<T>(scene, *m, guess, duration);
    });
    limits.push_back({m, used, predicted, measured.step, measured.capped});
  }
  return limits;
}

// step_limits.csv and its chart.
void write_limits(const std::vector<MethodLimit>& limits, const StiffnessEstimate& e, double dt, const fs::path& dir) {
  OutputFile csv(dir / "step_limits.csv");
  csv << "method,stiffness,angle,predicted_step,measured_step,capped_by_duration\n";
  std::vector<StepLimit> chart;
  for (const MethodLimit& l : limits) {
    csv << l.method->name << ',' << l.estimate.magnitude << ',' << l.estimate.angle << ',' << l.predicted << ','
        << l.measured << ','
        << int(l.capped) << '\n';
    chart.push_back({std::string(l.method->name), l.predicted, l.measured});
  }
  csv.close();
  render_step_limits(dir, chart, e.magnitude, dt);
}

std::string table_row(const MethodLimit& l) {
  char ratio[32] = "-";
  if (l.predicted > 0 && std::isfinite(l.predicted) && std::isfinite(l.measured)) {
    std::snprintf(ratio, sizeof ratio, "%.2f%s", l.measured / l.predicted, l.broken() ? " *" : "");
  }
  if (l.capped) std::snprintf(ratio, sizeof ratio, "-");  // a lower bound has no ratio
  char measured[32];
  std::snprintf(measured, sizeof measured, "%s%.4g", l.capped ? ">= " : "", l.measured);
  char row[160];
  std::snprintf(row, sizeof row, "  %-18s %10.4g %10s   %s\n", std::string(l.method->name).c_str(), l.predicted,
                measured, ratio);
  return row;
}

bool is_orbit(const Scene& scene) {
  return scene.nbody || std::any_of(scene.forces.begin(), scene.forces.end(),
                                    [](const LocalTerm& t) { return std::holds_alternative<Central>(t); });
}

// What a * in the table means, and why the scene broke the bound.
std::string broken_note(const Scene& scene) {
  const std::string head = "* under 0.8 x predicted: the scene breaks the linear bound earlier. ";
  if (is_orbit(scene)) {
    return head + "On an orbit that mode is not the\n  orbit's turning, and the forces change along the orbit: "
                  "each step's error grows from orbit to orbit\n  until the energy is off by |E0|. The run fails "
                  "from lost accuracy, not from one mode's growth, and\n  at smaller steps the longer it runs "
                  "(--duration).\n";
  }
  return head + "The forces may change along the\n  motion (not linear in the state), or a slower but less damped "
                "mode may limit the method first.\n";
}

// The table people read: each method's predicted and measured limit, and what a * means.
std::string limits_table(const Scene& scene, const std::vector<MethodLimit>& limits, const StiffnessEstimate& e,
                         double duration) {
  char text[400];
  std::snprintf(text, sizeof text, "largest stable step (s):\n  %-18s %10s %10s   %s\n", "method", "predicted",
                "measured", "measured/predicted");
  std::string table = text;
  for (const MethodLimit& l : limits) table += table_row(l);
  std::snprintf(text, sizeof text,
                "predicted: where the fastest mode of the forces linearized about the start state would grow "
                "(|lambda| = %.4g /s)\nmeasured: the largest step whose run stays finite, its energy within |E0| "
                "of the start, over %g s (to 0.5%%)\n",
                e.magnitude, duration);
  table += text;
  const auto implicit = std::find_if(limits.begin(), limits.end(), [](const MethodLimit& l) {
    return l.method->kind == MethodKind::linearly_implicit;
  });
  if (implicit != limits.end()) {
    std::snprintf(text, sizeof text,
                  "implicit methods: predicted from the forces but the springs, which they step explicitly "
                  "(|lambda| = %.4g /s; the springs' modes bound no step)\n",
                  implicit->estimate.magnitude);
    table += text;
  }
  if (std::any_of(limits.begin(), limits.end(), [](const MethodLimit& l) { return l.broken(); })) {
    table += broken_note(scene);
  }
  if (std::any_of(limits.begin(), limits.end(), [](const MethodLimit& l) { return l.capped; })) {
    table += ">= every step up to the duration held (a step is never longer than the run): give a longer --duration\n";
  }
  return table;
}

// The scene's stiffness at its start (rigid bodies: over their rotation too).
StiffnessEstimate stiffness_of_scene(const Scene& scene) {
  const ForceModel<double> forces = make_forces<double>(scene);
  const ParticleSet<double> bodies = make_particles<double>(scene);
  if (bodies.size() > 0) return estimate_stiffness(bodies, forces, 0, 120, on_calling_thread(), interrupt_request());
  return estimate_stiffness(make_rigid_bodies<double>(scene), forces, 0, 120, on_calling_thread(), interrupt_request());
}

// Each method's largest stable step on this scene, predicted from the stiffness estimate at
// its start and measured over the duration, into step_limits.csv and a chart; returns the
// table to print.
std::string step_limits(const Scene& scene, const std::vector<const Method*>& methods, double dt, double duration,
                        const fs::path& dir) {
  const StiffnessEstimate e = stiffness_of_scene(scene);
  const bool implicit = std::any_of(methods.begin(), methods.end(),
                                    [](const Method* m) { return m->kind == MethodKind::linearly_implicit; });
  StiffnessEstimate explicit_e = e;
  if (implicit && !scene.springs.empty()) {
    Scene without = scene;
    without.springs.clear();
    explicit_e = stiffness_of_scene(without);
  }
  const std::vector<MethodLimit> limits = measure_limits(scene, methods, e, explicit_e, dt, duration);
  write_limits(limits, e, dt, dir);
  return limits_table(scene, limits, e, duration);
}

}  // namespace

// The runs' force evaluations, before the estimate gives each method's stable step: the
// energy run at dt, and about 16 bisection runs near the stable step, taken as dt here; the
// estimate's 137 (twice with an implicit method: the forces but the springs too); each energy
// point's potential sum about one evaluation.
double planned_evaluations(const std::vector<const Method*>& methods, std::uint64_t steps, bool nbody) {
  double evaluations = 137;
  for (const Method* m : methods) {
    evaluations += 17 * double(steps) * m->evaluations() + (nbody ? 100 : 0);
    if (m->kind == MethodKind::linearly_implicit) evaluations += 137;
  }
  return evaluations;
}

int stability_scene(const StabilityOptions& o) {
  const Scene full = load_checked(o.scene_path, o.precision);
  const Scene scene = sample_bodies(full, o.max_bodies);
  const double dt = o.dt.value_or(full.dt);
  const double duration = o.duration.value_or(full.dt * double(full.steps));
  const std::uint64_t steps = step_count(duration, dt);
  const std::vector<const Method*> methods = pick_methods(o.methods, full);
  check_work(o.scene_path, "stability", planned_evaluations(methods, steps, bool(scene.nbody)), scene,
             "give a shorter --duration, a longer --dt or fewer --methods");
  const fs::path dir = o.out;
  make_output_folder(dir);
  OutputFile energy_csv(dir / "energy.csv"), path_csv(dir / "trajectory.csv");
  energy_csv << "method,t,energy,relative_error\n";
  path_csv << "method,t,x,y,z\n";
  double max_z = 0;
  std::size_t plotted = 0;
  Progress progress("kinema stability", o.quiet);
  for (std::size_t i = 0; i < methods.size(); ++i) {
    stop_if_interrupted();
    const std::string name(methods[i]->name);
    OutputFile energy_dat(dir / ("energy_" + name + ".dat")), path_dat(dir / ("path_" + name + ".dat"));
    plotted += with_precision(scene.precision, [&]<class T>() {
      return record<T>(scene, *methods[i], dt, steps, energy_csv, path_csv, energy_dat, path_dat, max_z);
    });
    energy_dat.close();
    path_dat.close();
    progress.update(double(i + 1) / double(methods.size() + 1));
  }
  energy_csv.close();
  path_csv.close();
  if (plotted == 0) {
    throw Error("no energy chart: the relative energy error is not finite at any time (the "
                "initial energy is 0, or every method blew up at once); the values are in " +
                (dir / "energy.csv").string());
  }
  render_energy_chart(dir, scene.name, dt, methods);
  const bool planar = max_z == 0;
  if (planar) render_trajectory_chart(dir, scene.name, methods);
  write_regions(dir, methods);
  const std::string springs = spring_limits(scene, dir);
  const std::string steps_line = step_limits(scene, methods, dt, duration, dir);
  progress.finish();
  if (!o.quiet) {
    std::printf("kinema stability: %s, h = %g, %llu steps; wrote %s/{energy,trajectory,"
                "stability_region,thresholds,step_limits%s}.csv and charts%s\n",
                printable(scene.name).c_str(), dt, static_cast<unsigned long long>(steps),
                printable(o.out).c_str(), springs.empty() ? "" : ",spring_limit",
                planar ? "" : " (no trajectory chart: the motion is not planar)");
    std::fputs(springs.c_str(), stdout);
    std::fputs(steps_line.c_str(), stdout);
    if (o.methods.empty() && takes_implicit_methods(full)) {
      std::puts("implicit_euler and ros2 (springs implicit, predicted from the other forces) are drawn when named in "
                "--methods;\n  their measured limit bisects many solves, minutes on a large scene");
    }
  }
  return 0;
}

}  // namespace kinema::cli
