#include "kinema/accuracy.hpp"

#include "core/text.hpp"

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>

#include "forces/force_terms.hpp"
#include "kinema/diagnostics.hpp"
#include "kinema/error.hpp"
#include "kinema/job_system.hpp"
#include "kinema/stability.hpp"
#include "kinema/stepper.hpp"
#include "kinema/world.hpp"

namespace kinema {
namespace {

// The stop request of the analysis running on this thread: set by the outermost public
// call given one, read by every run inside it (pilots, references, the stiffness estimate).
thread_local const StopRequest* active_stop = nullptr;

class StopScope {
 public:
  explicit StopScope(const StopRequest& stop) : outer_(active_stop) {
    if (stop) active_stop = &stop;
  }
  ~StopScope() { active_stop = outer_; }
  StopScope(const StopScope&) = delete;
  StopScope& operator=(const StopScope&) = delete;

 private:
  const StopRequest* outer_;
};

const StopRequest& current_stop() {
  static const StopRequest none;
  return active_stop ? *active_stop : none;
}

template <class T>
BodyStates states_of(const World<T>& world) {
  const ParticleSet<T>& particles = world.particles;
  const RigidBodySet<T>& rigid = world.rigid;
  BodyStates out;
  auto widen = [](const auto& v) { return Vec3<double>{v[0], v[1], v[2]}; };
  for (std::size_t i = 0; i < particles.size(); ++i) {
    out.positions.push_back(widen(particles.position(i)));
    out.velocities.push_back(widen(particles.velocity(i)));
  }
  for (std::size_t i = 0; i < rigid.size(); ++i) {
    const auto q = rigid.orientation(i);
    out.positions.push_back(widen(rigid.centers().position(i)));
    out.velocities.push_back(widen(rigid.centers().velocity(i)));
    out.orientations.push_back({q[0], q[1], q[2], q[3]});
  }
  return out;
}

// A fixed-step run's final states and the conjugate-gradient iterations its implicit
// solves took (0 for the other methods).
struct CountedRun {
  BodyStates states;
  std::uint64_t solve_iterations = 0;
};

template <class T>
CountedRun run(const Scene& scene, const Method& method, std::uint64_t steps, double duration) {
  World<T> world(scene, method, on_calling_thread());
  if (world.advance(T(duration / double(steps)), steps, current_stop()) < steps) throw Stopped();
  return {states_of(world), world.particle_stepper().implicit_stats().iterations};
}

CountedRun simulate_counted(const Scene& scene, const Method& method, std::uint64_t steps, double duration) {
  return with_precision(scene.precision, [&]<class T>() { return run<T>(scene, method, steps, duration); });
}

template <class T>
AdaptiveRun run_adaptive(const Scene& scene, const Method& method, double tolerance, double duration,
                         double max_step) {
  World<T> world(scene, method, on_calling_thread());
  Tolerances t{tolerance, tolerance};
  t.max_step = max_step;
  const AdaptiveStats stats = world.advance_to(duration, t, {}, current_stop());  // an attempt too
  if (stats.stopped) throw Stopped();
  return {states_of(world), stats.evaluations};
}

// Every body under exactly one central attractor on a bound orbit: Kepler's equation in
// terms of the change of eccentric anomaly dE, solved by Newton, then the f and g functions.
struct Motion {
  Vec3<double> x, v;
};

std::optional<Motion> kepler(const Central& c, const BodySpec& b, double t) {
  Vec3<double> r0;
  for (int d = 0; d < 3; ++d) r0[d] = b.position[d] - c.center[d];
  const Vec3<double>& v0 = b.velocity;
  const double r = std::hypot(r0[0], r0[1], r0[2]);
  const double v2 = v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2];
  const double energy = v2 / 2 - c.mu / r;
  if (!(energy < 0) || !(r > 0)) return std::nullopt;  // not an ellipse
  const double a = -c.mu / (2 * energy), n = std::sqrt(c.mu / (a * a * a));
  const double e_sin = (r0[0] * v0[0] + r0[1] * v0[1] + r0[2] * v0[2]) / std::sqrt(c.mu * a);
  const double e_cos = 1 - r / a;
  // n t = dE + e sin E0 (1 - cos dE) - e cos E0 sin dE; its derivative r / a is positive.
  double de = n * t;
  for (int i = 0; i < 100; ++i) {
    const double f = de + e_sin * (1 - std::cos(de)) - e_cos * std::sin(de) - n * t;
    const double step = f / (1 + e_sin * std::sin(de) - e_cos * std::cos(de));
    de -= step;
    if (std::abs(step) < 1e-15 * std::max(1.0, std::abs(de))) break;
  }
  const double f = 1 - a / r * (1 - std::cos(de)), g = t - (de - std::sin(de)) / n;
  // r(t) = a (1 - e cos E); the time derivatives of f and g follow from dE/dt = n a / r.
  const double r1 = a * (1 - e_cos * std::cos(de) + e_sin * std::sin(de));
  const double fdot = -std::sqrt(c.mu * a) * std::sin(de) / (r * r1);
  const double gdot = 1 - a / r1 * (1 - std::cos(de));
  Motion m;
  for (int d = 0; d < 3; ++d) {
    m.x[d] = c.center[d] + f * r0[d] + g * v0[d];
    m.v[d] = fdot * r0[d] + gdot * v0[d];
  }
  return m;
}

// y'' + gamma y' + w2 y = accel, one component: {y(t), y'(t)}.
std::pair<double, double> linear_motion(double y0, double v0, double gamma, double w2,
                                        double accel, double t) {
  if (w2 == 0) {
    if (gamma == 0) return {y0 + v0 * t + 0.5 * accel * t * t, v0 + accel * t};
    const double vt = accel / gamma, decay = std::exp(-gamma * t);
    return {y0 + vt * t + (v0 - vt) * (1 - decay) / gamma, vt + (v0 - vt) * decay};
  }
  const double eq = accel / w2, y = y0 - eq, beta = gamma / 2, disc = beta * beta - w2;
  const double decay = std::exp(-beta * t);
  if (disc < 0) {
    const double wd = std::sqrt(-disc), b = (v0 + beta * y) / wd;
    const double c = std::cos(wd * t), s = std::sin(wd * t);
    return {eq + decay * (y * c + b * s), decay * (-beta * (y * c + b * s) + wd * (b * c - y * s))};
  }
  if (disc == 0) {
    const double b = v0 + beta * y;
    return {eq + (y + b * t) * decay, (b - beta * (y + b * t)) * decay};
  }
  const double root = std::sqrt(disc), r1 = -beta + root, r2 = -beta - root;
  const double a = (v0 - r2 * y) / (r1 - r2), e1 = std::exp(r1 * t), e2 = std::exp(r2 * t);
  return {eq + a * e1 + (y - a) * e2, r1 * a * e1 + r2 * (y - a) * e2};
}

}  // namespace

Scene sample_bodies(const Scene& scene, std::size_t max_bodies) {
  // Bodies that pull on each other are one system: a sample would be another scene.
  if (scene.nbody || !scene.springs.empty() || !scene.body_springs.springs.empty()) {
    max_bodies = std::numeric_limits<std::size_t>::max();
  }
  Scene out = scene;
  out.generate.reset();
  out.particles.clear();
  out.rigid_bodies.clear();
  const ParticleSet<double> p = make_particles<double>(scene);
  const std::size_t np = std::min(p.size(), max_bodies);
  for (std::size_t j = 0; j < np; ++j) {
    const std::size_t i = std::size_t((unsigned __int128)j * p.size() / np);  // no overflow
    const double inv = p.inv_mass()[i];
    out.particles.push_back({p.position(i), p.velocity(i), inv == 0 ? 1 : 1 / inv, inv == 0, p.applied_force(i), {}, {}});
    const BodyParameters<double>& own = p.parameters();
    if (own.used(BodyParameter::linear_damping)) out.particles.back().damping = p.linear_damping(i);
    if (own.used(BodyParameter::gravity_factor)) out.particles.back().gravity_factor = p.gravity_factor(i);
  }
  const RigidBodySet<double> r = make_rigid_bodies<double>(scene);
  const std::size_t nr = std::min(r.size(), max_bodies);
  for (std::size_t j = 0; j < nr; ++j) {
    const std::size_t i = std::size_t((unsigned __int128)j * r.size() / nr);
    RigidSpec b;
    b.position = r.centers().position(i);
    b.velocity = r.centers().velocity(i);
    b.orientation = r.orientation(i);
    b.angular_momentum = r.angular_momentum(i);
    b.kinematic = r.centers().inv_mass()[i] == 0;  // its mass and inertia are gone: any will do
    b.mass = b.kinematic ? 1 : 1 / r.centers().inv_mass()[i];
    for (int d = 0; d < 3; ++d) b.inertia[d] = b.kinematic ? 1 : 1 / r.inv_inertia(d)[i];
    b.force = r.applied_force(i);
    b.torque = r.applied_torque(i);
    const BodyParameters<double>& own = r.parameters();
    if (own.used(BodyParameter::linear_damping)) b.damping = r.linear_damping(i);
    if (own.used(BodyParameter::angular_damping)) b.angular_damping = r.angular_damping(i);
    if (own.used(BodyParameter::gravity_factor)) b.gravity_factor = r.gravity_factor(i);
    out.rigid_bodies.push_back(b);
  }
  return out;
}

BodyStates simulate(const Scene& scene, const Method& method, std::uint64_t steps,
                    double duration, const StopRequest& stop) {
  if (steps == 0) throw Error("simulate: steps must be at least 1");
  const StopScope scope(stop);
  return simulate_counted(scene, method, steps, duration).states;
}

AdaptiveRun simulate_adaptive(const Scene& scene, const Method& method, double tolerance, double duration,
                              double max_step, const StopRequest& stop) {
  const StopScope scope(stop);
  return with_precision(scene.precision, [&]<class T>() {
    return run_adaptive<T>(scene, method, tolerance, duration, max_step);
  });
}

double state_error(const BodyStates& a, const BodyStates& b) {
  if (a.positions.size() != b.positions.size() || a.velocities.size() != b.velocities.size() ||
      a.orientations.size() != b.orientations.size() || a.velocities.size() != a.positions.size()) {
    throw Error("state_error: the states hold " + std::to_string(a.positions.size()) + " bodies (" +
                std::to_string(a.orientations.size()) + " orientations), the reference " +
                std::to_string(b.positions.size()) + " (" + std::to_string(b.orientations.size()) +
                "), or positions and velocities differ in number");
  }
  double worst = 0;
  auto distance = [](const Vec3<double>& p, const Vec3<double>& q) {
    return std::hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
  };
  for (std::size_t i = 0; i < a.positions.size(); ++i) {
    const double e = distance(a.positions[i], b.positions[i]) + distance(a.velocities[i], b.velocities[i]);
    if (!std::isfinite(e)) return std::numeric_limits<double>::infinity();
    worst = std::max(worst, e);
  }
  for (std::size_t i = 0; i < a.orientations.size(); ++i) {
    double minus = 0, plus = 0;
    for (int k = 0; k < 4; ++k) {
      minus += std::pow(a.orientations[i][k] - b.orientations[i][k], 2);
      plus += std::pow(a.orientations[i][k] + b.orientations[i][k], 2);
    }
    // |q - r| = 2 sin(angle / 4) for unit quaternions.
    const double chord = std::sqrt(std::min(minus, plus));
    if (!std::isfinite(chord)) return std::numeric_limits<double>::infinity();
    worst = std::max(worst, 4 * std::asin(std::min(1.0, chord / 2)));
  }
  return worst;
}

std::optional<BodyStates> analytic_states(const Scene& scene, double t) {
  if (!std::isfinite(t) || t < 0) {
    throw Error("analytic_states: the duration must be finite and >= 0, got " + shortest_text(t));
  }
  if (!scene.rigid_bodies.empty() || (scene.generate && scene.generate->rigid)) return std::nullopt;
  if (scene.nbody || !scene.springs.empty()) return std::nullopt;  // coupled: no closed form
  // Gravity, linear drag and springs make one linear model; a lone central term an orbit.
  const LocalSums sums = sum_terms(scene.forces);
  int without_reference = 0;
  for (const LocalTerm& term : scene.forces) {
    visit_term(term, [&](const auto&, auto info) { without_reference += info.reference == ReferenceRule::none; });
  }
  const double drag = sums.linear, spring_k = sums.spring_k;
  const Vec3<double>&g = sums.gravity, &weighted_anchor = sums.weighted_anchor;
  const bool linear = sums.central_count == 0 && without_reference == 0;
  const bool kepler_only = sums.central_count == 1 && without_reference == 0 && drag == 0 &&
                           spring_k == 0 && g == Vec3<double>{};
  const Central central{sums.center[0], sums.mu[0]};  // the lone one, when kepler_only
  if (!linear && !kepler_only) return std::nullopt;
  const Scene explicit_scene = sample_bodies(scene, std::numeric_limits<std::size_t>::max());
  BodyStates out;
  for (const BodySpec& b : explicit_scene.particles) {
    Motion m;
    if (b.kinematic) {
      for (int d = 0; d < 3; ++d) m.x[d] = b.position[d] + b.velocity[d] * t, m.v[d] = b.velocity[d];
    } else if (kepler_only) {
      if (b.force != Vec3<double>{} || b.damping.value_or(0) != 0) return std::nullopt;  // no closed form
      const auto k = kepler(central, b, t);
      if (!k) return std::nullopt;
      m = *k;
    } else {
      const double gamma = drag / b.mass + b.damping.value_or(0), w2 = spring_k / b.mass;
      for (int d = 0; d < 3; ++d) {
        // y = x - anchor under y'' + gamma y' + w2 y = g (the spring pulls to its anchor).
        const double anchor = spring_k > 0 ? weighted_anchor[d] / spring_k : 0;
        // The body's applied force is one more constant acceleration.
        const double a = g[d] * b.gravity_factor.value_or(1) + b.force[d] / b.mass;
        const auto [y, v] = linear_motion(b.position[d] - anchor, b.velocity[d], gamma, w2, a, t);
        m.x[d] = anchor + y, m.v[d] = v;
      }
    }
    out.positions.push_back(m.x);
    out.velocities.push_back(m.v);
  }
  return out;
}

Reference reference_states(const Scene& scene, double duration, std::uint64_t steps, const StopRequest& stop) {
  const StopScope scope(stop);
  if (auto exact = analytic_states(scene, duration)) return {*exact, 0, true, 0};
  Scene precise = scene;
  precise.precision = Precision::dual;
  const std::uint64_t half = std::max<std::uint64_t>(1, steps / 2);
  Reference ref;
  ref.states = simulate(precise, rk4, 2 * half, duration);
  ref.error = state_error(ref.states, simulate(precise, rk4, half, duration)) / 15;
  ref.steps = 2 * half;
  return ref;
}

namespace {

// The whole search may run this many body-steps of pilots (a few seconds on one core):
// a tolerance no method reaches, or a scene that blows up at every step size, ends there.
// A sample smaller than kChargedBodies is charged as that many: a step of a handful of
// bodies costs about as much (padding, per-step overhead).
constexpr double kSearchBodySteps = double(1 << 28);
constexpr double kChargedBodies = 64;
// A method's pilots stop at 4 x 2^22 steps.
constexpr std::uint64_t kMostPilotSteps = std::uint64_t(1) << 22;

struct SearchSpent {};  // thrown when the next pilot would pass kSearchBodySteps

// What one step of the pilot scene is charged, in body-steps: its bodies, or under N-body
// gravity its bodies squared (an interaction costs about what a body's local terms do).
double charged_bodies(const Scene& scene) {
  const double n = double(scene.particles.size() + scene.rigid_bodies.size());
  return std::max(kChargedBodies, scene.nbody ? n * n : n);
}

// Pilot runs of one method on a sample of bodies, memoized by step count; every run is
// charged to `spent` (body-steps).
class Pilot {
 public:
  // Its runs may take `spent` up to `limit` body-steps.
  Pilot(const Scene& scene, const Method& method, double duration, double& spent, double limit = kSearchBodySteps)
      : scene_(scene), method_(method), duration_(duration), spent_(spent), limit_(limit),
        bodies_(charged_bodies(scene)) {}

  // Error estimate of the n-step run, from runs at n, 2n and 4n: the difference d of the
  // first two times 2^p / (2^p - 1), p the observed order (capped by the nominal one).
  double estimate(std::uint64_t n) {
    const double d1 = state_error(at(n).states, at(2 * n).states), d2 = state_error(at(2 * n).states, at(4 * n).states);
    if (!std::isfinite(d1) || !std::isfinite(d2)) return std::numeric_limits<double>::infinity();
    const double nominal = method_.order;
    const double p = d1 > 0 && d2 > 0 ? std::clamp(std::log2(d1 / d2), 0.5, nominal) : nominal;
    return estimates_[n] = d1 * std::pow(2.0, p) / (std::pow(2.0, p) - 1);
  }

  // Whether the estimates of the two finest runs so far did not fall as the steps doubled:
  // the finer run's steps, the coarser estimate and the finer one. A method of order p >= 1
  // divides its error by 2^p a doubling once its steps resolve the motion; where more steps
  // do not shrink it, the run's end hangs on round-off or on each step's error.
  struct Stall {
    std::uint64_t steps;
    double coarser, finer;
  };
  std::optional<Stall> stall() const {
    if (estimates_.size() < 2) return std::nullopt;
    const auto finer = std::prev(estimates_.end()), coarser = std::prev(finer);
    if (finer->second < coarser->second) return std::nullopt;  // estimates are finite when kept
    return Stall{finer->first, coarser->second, finer->second};
  }

  // The n-step run's cost in force evaluations, an implicit solve's iteration counted as
  // one (a product over every spring slot costs about what an evaluation of the springs does).
  double cost(std::uint64_t n) { return double(n) * method_.evaluations() + double(at(n).solve_iterations); }
  const BodyStates& states(std::uint64_t n) { return at(n).states; }

 private:
  const CountedRun& at(std::uint64_t n) {
    auto it = runs_.find(n);
    if (it == runs_.end()) {
      // An implicit run's solves cost about a step an iteration: as many a step as the
      // most the earlier runs took, and what this one took is charged after it.
      if (spent_ + double(n) * (1 + iterations_per_step_) * bodies_ > limit_) throw SearchSpent{};
      spent_ += double(n) * bodies_;
      it = runs_.emplace(n, simulate_counted(scene_, method_, n, duration_)).first;
      const double iterations = double(it->second.solve_iterations);
      spent_ += iterations * bodies_;
      iterations_per_step_ = std::max(iterations_per_step_, iterations / double(n));
      if (spent_ > limit_) throw SearchSpent{};
    }
    return it->second;
  }

  const Scene& scene_;
  const Method& method_;
  double duration_;
  double& spent_;
  double limit_;
  double iterations_per_step_ = 0;
  double bodies_;
  std::map<std::uint64_t, CountedRun> runs_;
  std::map<std::uint64_t, double> estimates_;  // by step count
};

// The fewest steps (to within a factor 4/3) whose estimated error stays under the
// tolerance: halve or double from n, then try three quarters of the last good count.
// Gives up once the steps would cost more force evaluations than `budget` (their
// evaluations alone: an implicit method's solves come on top, in Pilot::cost).
std::optional<std::uint64_t> steps_needed(Pilot& pilot, const Method& m, std::uint64_t n,
                                          double tolerance, double budget, std::uint64_t least) {
  auto fits = [&](std::uint64_t k) { return pilot.estimate(k) <= tolerance; };
  auto affordable = [&](std::uint64_t k) { return double(k) * m.evaluations() <= budget; };
  // A stable step that already costs too much rules the method out before any pilot runs.
  if (least > kMostPilotSteps || !affordable(least)) return std::nullopt;
  n = std::max(n, least);
  if (fits(n)) {
    while (n / 2 >= std::max<std::uint64_t>(least, 1) && fits(n / 2)) n /= 2;
  } else {
    do {
      n *= 2;
      if (!affordable(n) || n > kMostPilotSteps) return std::nullopt;
    } while (!fits(n));
  }
  const std::uint64_t three_quarters = std::max<std::uint64_t>({1, least, 3 * n / 4});
  if (three_quarters < n && fits(three_quarters)) n = three_quarters;
  if (!affordable(n)) return std::nullopt;
  return n;
}

// Error-controlled runs of an embedded pair: the loosest rtol = atol, from the tolerance
// down by tens, whose error (against a run a hundred times tighter) stays under it, with
// the force evaluations it takes; nullopt when none does within the budget.
struct AdaptivePick {
  double step_tolerance;
  double evaluations;
  double estimated_error;
};
std::optional<AdaptivePick> adaptive_pick(const Scene& scene, const Method& m, double duration, double tolerance,
                                          double max_step, double budget, double& spent) {
  const double bodies = charged_bodies(scene);
  // Steps no longer than max_step: a run's fewest, known before it starts. A stable step far
  // under the duration (a stiff scene) would otherwise spend past the search's bound in one run.
  // (Each step makes at least stages - 1 evaluations: the first may be the last one's.)
  const double fewest_evaluations = std::ceil(duration / max_step) * double(m.evaluations() - 1);
  if (fewest_evaluations > budget) return std::nullopt;
  const auto run = [&](double tau) {
    if (spent + fewest_evaluations / m.tableau.stages * bodies > kSearchBodySteps) throw SearchSpent{};
    AdaptiveRun r = simulate_adaptive(scene, m, tau, duration, max_step);
    spent += double(r.evaluations) / m.tableau.stages * bodies;
    if (spent > kSearchBodySteps) throw SearchSpent{};
    return r;
  };
  for (double tau = tolerance; tau >= tolerance * 1e-8; tau /= 10) {
    const AdaptiveRun loose = run(tau);
    if (double(loose.evaluations) > budget) return std::nullopt;
    const double error = state_error(loose.states, run(tau / 100).states);
    if (error <= tolerance) return AdaptivePick{tau, double(loose.evaluations), error};
  }
  return std::nullopt;
}

// The scene's stiffness at its start, in double, on its particles (else the rigid bodies,
// their rotation too).
StiffnessEstimate stiffness_of(const Scene& scene) {
  const ParticleSet<double> bodies = make_particles<double>(scene);
  const ForceModel<double> forces = make_forces<double>(scene);
  if (bodies.size() > 0) return estimate_stiffness(bodies, forces, 0, 120, on_calling_thread(), current_stop());
  return estimate_stiffness(make_rigid_bodies<double>(scene), forces, 0, 120, on_calling_thread(), current_stop());
}

// Refuses at once a tolerance below the round-off of a single step: a few units in the
// last place of the largest |x| + |v| among the bodies.
void check_reachable(const Scene& sample, double tolerance) {
  double scale = 0;
  auto size = [](const Vec3<double>& v) { return std::hypot(v[0], v[1], v[2]); };
  for (const BodySpec& b : sample.particles) scale = std::max(scale, size(b.position) + size(b.velocity));
  for (const RigidSpec& b : sample.rigid_bodies) scale = std::max(scale, size(b.position) + size(b.velocity));
  const double epsilon = sample.precision == Precision::single ? 0x1p-23 : 0x1p-52;
  const double floor = 4 * epsilon * scale;
  if (tolerance < floor) {
    char text[256];
    std::snprintf(text, sizeof text,
                  "auto: tolerance %g is below the round-off of one step in %s on this scene "
                  "(about %.2g: 4 ulp of its largest |x| + |v|); no method can reach it",
                  tolerance, std::string(precision_name(sample.precision)).c_str(), floor);
    throw Error(text);
  }
}

}  // namespace

namespace {

// Float where the chosen configuration's round-off in float, against the same run in double,
// stays ten times under the tolerance (with the truncation error, under it).
void consider_float(const Scene& pilot_scene, double duration, double tolerance, double max_step,
                    MethodChoice& choice) {
  if (pilot_scene.precision != Precision::dual) return;
  Scene single = pilot_scene;
  single.precision = Precision::single;
  try {
    check_scene<float>(single);
  } catch (const Error&) {
    return;  // values float cannot hold
  }
  const auto states = [&](const Scene& s) {
    return choice.step_tolerance ? simulate_adaptive(s, *choice.method, *choice.step_tolerance, duration, max_step).states
                                 : simulate(s, *choice.method, choice.steps, duration);
  };
  double roundoff = 0;
  try {
    roundoff = state_error(states(single), states(pilot_scene));
  } catch (const Error&) {
    return;  // float cannot take the run (error control asked for less than its round-off)
  }
  if (roundoff <= tolerance / 10 && choice.estimated_error + roundoff <= tolerance) {
    choice.precision = Precision::single;
    char text[160];
    std::snprintf(text, sizeof text, "; float's round-off %.2g is under a tenth of the tolerance: run in float",
                  roundoff);
    choice.reason += text;
  }
}

// The search of choose_method: every candidate tried in turn against the cheapest so far,
// each one's cost (in force evaluations) written into the reason.
// A pilot's error as a note: up to its first ';' ("advance_to: the step size underflows at t = 46.1").
std::string first_clause(const std::string& message) { return message.substr(0, message.find(';')); }

class MethodSearch {
 public:
  MethodSearch(const Scene& scene, double tolerance, bool float_allowed)
      : duration_(scene.dt * double(scene.steps)), tolerance_(tolerance), float_allowed_(float_allowed),
        pilot_scene_(sample_bodies(scene, 64)) {
    check_reachable(pilot_scene_, tolerance);
    stiffness_ = stiffness_of(pilot_scene_);
    start_ = std::clamp<std::uint64_t>(scene.steps / 16, 8, kMostPilotSteps);
    choice_.precision = scene.precision;
  }

  // Fixed steps with every method that may take them, highest order first: it usually sets
  // the budget the others must beat. Rigid bodies try the built-in methods only: the others
  // run on the rigid path, at two to three times the fused cost per evaluation. Returns
  // whether search budget is left.
  bool search_fixed_steps() {
    std::vector<const Method*> order(builtin_methods.begin(), builtin_methods.end());
    if (pilot_scene_.rigid_bodies.empty()) order.insert(order.end(), staged_methods.begin(), staged_methods.end());
    std::stable_sort(order.begin(), order.end(), [](auto* a, auto* b) { return a->order > b->order; });
    // The implicit methods right after the first explicit one that meets the tolerance,
    // whose run they are checked against (checked_implicit), before the search budget goes.
    bool implicit_left = takes_implicit_methods(pilot_scene_);
    for (const Method* m : order) {
      if (!fixed_steps_leave_budget(*m)) return false;
      if (implicit_left && reference_) {
        implicit_left = false;
        for (const Method* i : implicit_methods) {
          if (!fixed_steps_leave_budget(*i)) return false;
        }
      }
    }
    flush_too_stiff(order.size());
    if (implicit_left) note("the implicit methods not tried (no explicit method met the tolerance to check them against)");
    return true;
  }

  // Error-controlled steps (particles only), within the stable step.
  void search_error_control() {
    if (!pilot_scene_.rigid_bodies.empty()) return;
    for (const Method* m : {&dopri5, &bs3}) {
      if (!error_control_leaves_budget(*m)) return;
    }
  }

  MethodChoice result() {
    flush_too_stiff(0);
    if (choice_.method == nullptr) refuse();
    choice_.evaluations = best_cost_;
    if (!choice_.step_tolerance) choice_.dt = duration_ / double(choice_.steps);
    char head[96];
    std::snprintf(head, sizeof head, "for error <= %g over %g s, in force evaluations: ", tolerance_, duration_);
    char tail[96];
    std::snprintf(tail, sizeof tail, "; picked %s%s (%.0f evaluations)", std::string(choice_.method->name).c_str(),
                  choice_.step_tolerance ? " with error control" : "", best_cost_);
    choice_.reason = head + reason_ + tail;
    if (!float_allowed_) return choice_;
    const double stable = stable_step(*choice_.method);
    consider_float(pilot_scene_, duration_, tolerance_, stable > 0 ? stable : std::numeric_limits<double>::infinity(),
                   choice_);
    return choice_;
  }

 private:
  void note(const std::string& text) { reason_ += (reason_.empty() ? "" : ", ") + text; }
  // Methods whose largest stable step alone takes more pilot steps than the search allows:
  // one note for all of them, the first one's step named (a scene stiff for one is for all).
  void note_too_stiff(const Method& m, double stable, double steps) {
    if (too_stiff_.empty()) {
      char text[128];
      std::snprintf(text, sizeof text, " (%s: %.2g of %.2g s)", std::string(m.name).c_str(), steps, stable);
      too_stiff_step_ = text;
    }
    too_stiff_.push_back(std::string(m.name));
  }
  // `tried`: how many methods the search tried; all of them too stiff are named as such.
  void flush_too_stiff(std::size_t tried) {
    if (too_stiff_.empty()) return;
    const bool all = too_stiff_.size() == tried, one = all || too_stiff_.size() == 1;
    std::string names = all ? "every explicit method" : too_stiff_.front();
    for (std::size_t i = 1; !all && i < too_stiff_.size(); ++i) names += ", " + too_stiff_[i];
    note(names + (one ? " needs" : " need") + " over 2^22 steps to stay stable" + too_stiff_step_);
    too_stiff_.clear();
  }

  // The largest stable step of m on the scene: an implicit method's on the scene without its
  // springs (the forces it steps explicitly: ImplicitMode::explicit_forces).
  double stable_step(const Method& m) {
    if (m.kind != MethodKind::linearly_implicit) return largest_stable_step(m, stiffness_);
    if (!explicit_stiffness_) {
      Scene without = pilot_scene_;
      without.springs.clear();
      explicit_stiffness_ = stiffness_of(without);
    }
    return largest_stable_step(m, *explicit_stiffness_, ImplicitMode::explicit_forces);
  }

  // Tries m at fixed steps; false when the search budget ran out on it.
  bool fixed_steps_leave_budget(const Method& m) {
    const double stable = stable_step(m);
    if (!(stable > 0)) {
      note(std::string(m.name) + " unstable here");
      return true;
    }
    const double fewest = std::isfinite(stable) ? std::ceil(duration_ / stable) : 1;
    if (fewest > double(kMostPilotSteps)) {
      if (m.kind != MethodKind::linearly_implicit) return note_too_stiff(m, stable, fewest), true;
      char text[128];  // the explicit ones' note counts them alone
      std::snprintf(text, sizeof text, " needs over 2^22 steps to stay stable (%.2g of %.2g s)", fewest, stable);
      note(std::string(m.name) + text);
      return true;
    }
    const auto least = std::uint64_t(fewest);
    // An implicit method's pilots may take a quarter of the budget left: a scene where its
    // estimates never settle must not cost the explicit methods still to come their turn.
    const bool implicit = m.kind == MethodKind::linearly_implicit;
    Pilot pilot(pilot_scene_, m, duration_, spent_,
                implicit ? spent_ + (kSearchBodySteps - spent_) / 4 : kSearchBodySteps);
    std::optional<std::uint64_t> steps;
    double estimated = 0;
    try {
      steps = steps_needed(pilot, m, start_, tolerance_, best_cost_, least);
      if (steps) estimated = pilot.estimate(*steps);
      if (steps && implicit) {
        const auto checked = checked_implicit(pilot, m, *steps);
        if (!checked) return true;
        steps = checked->first, estimated = checked->second;
      }
    } catch (const SearchSpent&) {
      if (implicit) {
        note(std::string(m.name) + " not settled within its share of the search budget");
        return true;
      }
      if (note_stall(pilot, m, " and spent the search budget")) return false;
      // A best so far meets the tolerance and may not be the cheapest; or none does yet.
      note(std::string(m.name) + (std::isfinite(best_cost_) ? " not tried (search budget spent)"
                                                             : " ran out of the search budget before meeting it"));
      return false;
    } catch (const Error& e) {
      note(std::string(m.name) + " failed (" + first_clause(e.what()) + ")");
      return true;
    }
    if (!steps) {
      if (!note_stall(pilot, m, "")) note(std::string(m.name) + (std::isfinite(best_cost_) ? " costlier" : " cannot"));
      return true;
    }
    const double cost = pilot.cost(*steps);
    note(std::string(m.name) + " " + std::to_string(std::uint64_t(cost)) + " (" + std::to_string(*steps) +
         " steps" + (implicit ? ", with their solves' iterations)" : ")"));
    choice_.candidates.push_back({&m, *steps, cost});
    if (!implicit && !reference_) reference_ = ExplicitRun{pilot.states(*steps), estimated, &m};
    if (cost < best_cost_) {
      best_cost_ = cost;
      choice_.method = &m;
      choice_.steps = *steps;
      choice_.estimated_error = estimated;
    }
    return true;
  }

  // While nothing meets the tolerance: notes that m's estimates did not settle, if so.
  bool note_stall(const Pilot& pilot, const Method& m, const char* then) {
    const auto stall = pilot.stall();
    if (!stall || std::isfinite(best_cost_)) return false;
    char text[160];
    std::snprintf(text, sizeof text, " did not settle (its error estimate %.2g at %llu steps, %.2g at half as many)%s",
                  stall->finer, static_cast<unsigned long long>(stall->steps), stall->coarser, then);
    note(std::string(m.name) + text);
    unsettled_ = true;
    return true;
  }

  // Richardson on an implicit method's pilots can agree with itself and not with the truth:
  // with steps far past the stiff modes (h |lambda| >> 1) every pilot may lose the same
  // motion (a stiff spring turning with its bodies is slowed at each step as the others are).
  // So the steps are checked against the run of the first explicit method that met the
  // tolerance (the highest order's, usually the most accurate), doubled (at most three
  // times) until they agree within it; the steps and that error, or nullopt (noted).
  std::optional<std::pair<std::uint64_t, double>> checked_implicit(Pilot& pilot, const Method& m, std::uint64_t n) {
    const std::string name(m.name);
    const std::string against = " against " + std::string(reference_->method->name) + "'s run";
    try {
      for (const std::uint64_t last = 8 * n;
           n <= std::min(last, kMostPilotSteps) && double(n) * m.evaluations() <= best_cost_; n *= 2) {
        const double error = state_error(pilot.states(n), reference_->states) + reference_->error;
        if (error <= tolerance_) return std::pair{n, error};
      }
    } catch (const SearchSpent&) {
      note(name + " not checked" + against + " within its share of the search budget");
      return std::nullopt;
    }
    note(name + " misses the tolerance" + against);
    return std::nullopt;
  }

  // Tries m with error control; false when the search budget ran out on it.
  bool error_control_leaves_budget(const Method& m) {
    const double stable = largest_stable_step(m, stiffness_);
    if (!(stable > 0)) return true;
    std::optional<AdaptivePick> pick;
    try {
      pick = adaptive_pick(pilot_scene_, m, duration_, tolerance_, stable, best_cost_, spent_);
    } catch (const SearchSpent&) {
      return false;
    } catch (const Error& e) {  // a pilot that cannot go on (its step underflows): not a candidate
      note(std::string(m.name) + " with error control failed (" + first_clause(e.what()) + ")");
      return true;
    }
    if (!pick) return true;
    char text[120];
    std::snprintf(text, sizeof text, "%s with error control (rtol = atol = %g) %.0f", std::string(m.name).c_str(),
                  pick->step_tolerance, pick->evaluations);
    note(text);
    if (pick->evaluations < best_cost_) {
      best_cost_ = pick->evaluations;
      choice_.method = &m;
      choice_.step_tolerance = pick->step_tolerance;
      choice_.estimated_error = pick->estimated_error;
    }
    return true;
  }

  [[noreturn]] void refuse() const {
    char text[256];
    std::snprintf(text, sizeof text,
                  "auto: no method reaches tolerance %g within 2^22 steps or 2^28 body-steps of "
                  "pilot runs (give --method and --dt, or a larger tolerance%s)", tolerance_,
                  choice_.precision == Precision::single ? "; in float, try double" : "");
    std::string message = text;
    if (!reason_.empty()) message += "; " + reason_;
    if (unsettled_) {
      message += ". Where more steps do not shrink the error, the end of the run likely hangs on round-off or on "
                 "every step's error (a buckling, tumbling or chaotic scene): a shorter run may have an answer";
    }
    throw Error(message);
  }

  double duration_, tolerance_;
  bool float_allowed_;
  Scene pilot_scene_;
  StiffnessEstimate stiffness_;
  std::optional<StiffnessEstimate> explicit_stiffness_;  // without the springs, when asked
  // The first explicit run that met the tolerance: its final states and estimated error.
  struct ExplicitRun {
    BodyStates states;
    double error;
    const Method* method;
  };
  std::optional<ExplicitRun> reference_;
  std::uint64_t start_ = 0;
  MethodChoice choice_;
  double best_cost_ = std::numeric_limits<double>::infinity(), spent_ = 0;
  std::string reason_;
  std::vector<std::string> too_stiff_;  // note_too_stiff's methods
  std::string too_stiff_step_;
  bool unsettled_ = false;  // a method's estimates did not settle while none met the tolerance
};

}  // namespace

MethodChoice choose_method(const Scene& scene, double tolerance, const StopRequest& stop, bool float_allowed) {
  const StopScope scope(stop);
  if (!(std::isfinite(tolerance) && tolerance > 0)) {
    throw Error("tolerance must be positive and finite");
  }
  if (scene.steps == 0) throw Error("auto: the scene has no steps to choose a step size for");
  MethodSearch search(scene, tolerance, float_allowed);
  if (search.search_fixed_steps()) search.search_error_control();
  return search.result();
}

}  // namespace kinema
