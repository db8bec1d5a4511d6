#include "step/adaptive_driver.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <span>
#include <string>
#include <tuple>

#include "core/text.hpp"
#include "kernels/reductions.hpp"
#include "kinema/error.hpp"
#include "kinema/files.hpp"
#include "step/finite_guard.hpp"
#include "step/step_controller.hpp"

namespace kinema {
namespace {

// An accepted step's scan, from the attempt's start `before` to the set's state `after` (their
// first six arrays: px .. vz); at a stop event `settle` puts the set there (a stop at the
// step's end needs none) and the clock goes to the hit's own time. A throwing event function,
// or a settle whose host enqueue throws, puts the step back (`take_back`), the clock and the
// step's hits too.
template <class T, class TakeBack, class Settle>
bool scanned_to_stop(const AdaptiveEvents<T>& events, const Workers& workers, const T* const* before,
                     const T* const* after, std::size_t padded, Clock<T>& clock, const Clock<T>& start, double h,
                     TakeBack&& take_back, Settle&& settle) {
  const std::size_t kept = events.watch->hits().size();
  try {
    events.watch->scan_blocks(workers, events.call, before, after, padded, start.time(), h);
    const auto stop = events.watch->first_stop();
    if (!stop) return false;
    if (stop->theta < 1) settle(*stop);
    clock.set(stop->time);  // the hit's own time, also at a last step's end
    return true;
  } catch (...) {
    clock = start;  // first: a take-back whose own enqueue throws puts the bodies back, then throws
    events.watch->rollback(kept);  // the step's hits go with it, a stop among them too
    take_back();
    throw;
  }
}

// The size of the next attempt from t toward t_end: h, capped at max_step (h keeps the cap);
// no sliver of a last step: one within 1% of the end takes the rest, if max_step allows.
template <class T>
struct NextAttempt {
  T size;
  bool last;
};
template <class T>
NextAttempt<T> next_attempt(double t, double t_end, double& h, double max_step) {
  h = std::min(h, max_step);
  const bool last = t + 1.01 * h >= t_end && t_end - t <= max_step;
  return {T(last ? t_end - t : h), last};
}

// A step size that no longer moves the clock.
template <class T>
bool underflows(double t, T size) {
  return !(size > 0) || t + double(size) == t;
}

std::string underflow_message(double t, const std::string& type) {
  return "advance_to: the step size underflows at t = " + shortest_text(t) + "; the tolerances cannot be met in " + type;
}

template <class T>
std::uint32_t crc_of_array(const T* a, std::size_t n, std::uint32_t crc) {
  return a == nullptr ? crc : crc32c(std::as_bytes(std::span<const T>(a, n)), crc);
}

// The first step of a call (Hairer's): 0.01 |y| / |f(y)| in the error's weighted RMS norm, from
// squares(rtol, atol), the sums of squares of the weighted y and f(y) over `components`
// values; 1e-6 where either is tiny; at most span.
template <class Squares>
double starting_step(const Squares& squares, double components, const Tolerances& tol, double span) {
  auto [y2, f2] = squares(tol.rtol, tol.atol);
  // Weights 1 / atol past 1e154 (a component at zero under a tiny atol) square to inf: the
  // norms then come from weights 2^-600 of theirs, the thresholds scaled alike.
  double weight = 1;
  if (!std::isfinite(y2) || !std::isfinite(f2)) {
    weight = 0x1p-600;
    std::tie(y2, f2) = squares(tol.rtol / weight, tol.atol / weight);
  }
  const double d0 = std::sqrt(y2 / components), d1 = std::sqrt(f2 / components);
  const double h = d0 < 1e-5 * weight || d1 < 1e-5 * weight ? 1e-6 : 0.01 * d0 / d1;
  return std::min(h, span);
}

void count_accepted(AdaptiveStats& stats, double size) {
  ++stats.accepted;
  stats.smallest_step = stats.accepted == 1 ? size : std::min(stats.smallest_step, size);
  stats.largest_step = std::max(stats.largest_step, size);
}

template <class T>
class AdaptiveRun {
 public:
  AdaptiveRun(StepperCore<T>& core, const Workers& workers, ParticleSet<T>& bodies, const Tolerances& tolerances,
              const AdaptiveEvents<T>& events)
      : core_(core), staged_(*core.paths.staged), workers_(workers), bodies_(bodies), tol_(tolerances), events_(events) {}

  AdaptiveStats to(double t_end, double max_step, AdaptiveContinuation& continuation, const CallStops& stops) {
    staged_.reserve(bodies_.padded_size());
    interrupt_ = stops.interrupt;
    double t = core_.clock.time();
    const bool continues = continuation.active && continuation.max_step == max_step;  // checked by the stepper
    continuation.active = false;
    if (t_end == t) return stats_;
    const Method& method = core_.method;
    StepController controller(std::min(method.order, method.embedded_order));
    double h = 0;
    if (continues) {
      h = continuation.h, kept_scale_ = T(continuation.kept_scale);
      controller.set_state(continuation.controller);
    } else if (tol_.initial_step > 0) {
      h = tol_.initial_step;
    } else {
      try {
        h = first_step(t_end - t);
      } catch (const Stopped&) {  // nothing kept: the next call starts over, as this one did
        stats_.stopped = true;
        return stats_;
      }
    }
    while (t < t_end) {
      const auto [size, last] = next_attempt<T>(t, t_end, h, max_step);
      if (underflows(t, size)) underflow(t);
      const StepContext<T> c = start_attempt(size);
      last_size_ = size;
      double err = 0;
      try {
        err = staged_.attempt(c, {tol_.rtol, tol_.atol, reuse_scale(c)});
      } catch (const Stopped&) {
        abandon(c);
        keep_for_next_call(t_end, max_step, h, controller, continuation);
        break;
      }
      stats_.evaluations += std::uint64_t(method.tableau.stages - (kept_scale_ > 0 ? 1 : 0));
      const bool accepted = err <= 1;
      if (accepted) {
        const Clock<T> start = core_.clock;
        accept(size, last, t_end, c);
        if (events_.watch && stops_at_event(c, start)) break;
        t = core_.clock.time();
      } else {
        reject(c);
      }
      h = controller.next(double(size), err, accepted);
      if (accepted && t < t_end && stops.after_step()) {
        keep_for_next_call(t_end, max_step, h, controller, continuation);
        break;
      }
    }
    stats_.next_step = h;
    return stats_;
  }

 private:
  StepContext<T> start_attempt(T size) {
    StepContext<T> c = core_.start(bodies_, size, core_.lowered().particle, workers_, true);
    c.t0 = core_.clock.time();
    c.stop = interrupt_;
    return c;
  }

  // What the next call to t_end goes on from: the step size to try, the controller's state
  // and the acceleration scale of the first stage kept.
  void keep_for_next_call(double t_end, double max_step, double h, const StepController& controller,
                          AdaptiveContinuation& continuation) {
    continuation = {true, t_end, tol_.rtol, tol_.atol, max_step, h, controller.state(), double(kept_scale_),
                    bodies_.size(), stage_inputs_digest(bodies_)};
    stats_.stopped = true;
  }

  // An attempt stopped inside (taken back). Stopping polls only in coupled passes, and with a
  // first stage kept, the first poll comes after the stage pass that rescaled all of it to
  // this attempt's scale: it stays kept at that scale. Without one it was half evaluated.
  void abandon(const StepContext<T>& c) {
    kept_scale_ = kept_scale_ > 0 ? c.accel_scale : T(0);
  }

  // The accepted step's scan, both ends at hand (the attempt's start and the set); at a stop
  // event, the set and the clock go to it and the call ends. A throwing event function puts
  // the step back, and the clock.
  bool stops_at_event(const StepContext<T>& c, const Clock<T>& start) {
    const std::array<const T*, 6> before = staged_.attempt_start();
    const double h = double(c.h);
    return scanned_to_stop(
        events_, workers_, before.data(), state_arrays(bodies_).data.data(), bodies_.padded_size(), core_.clock,
        start, h, [&] { staged_.take_back(c); },
        [&](const typename EventWatch<T>::Stop& stop) {
          events_.watch->settle(workers_, bodies_, events_.call, before.data(), stop, h);
          kept_scale_ = 0;  // the kept stage was the step's end
        });
  }

  // Stage 0's kept accelerations, rescaled to this step's acceleration scale; 0: none kept.
  T reuse_scale(const StepContext<T>& c) const { return kept_scale_ > 0 ? c.accel_scale / kept_scale_ : T(0); }

  void accept(T size, bool last, double t_end, const StepContext<T>& c) {
    ++core_.clock.steps;
    if (last) core_.clock.set(t_end);
    count_accepted(stats_, double(size));
    const bool fsal = core_.method.tableau.first_same_as_last();
    if (fsal) staged_.keep_last_stage();
    kept_scale_ = fsal ? c.accel_scale : T(0);
  }

  // Names the body and component whose error forced the last step tried down: with thousands
  // of bodies, the one to look at.
  [[noreturn]] void underflow(double t) {
    std::string culprit;
    if (last_size_ > 0) try {
      // One more attempt of the last size tried, from here, taken back: its errors say who.
      const StepContext<T> c{bodies_, last_size_, core_.accel_scale(last_size_), t, workers_};
      staged_.attempt(c, {tol_.rtol, tol_.atol, T(0)});
      staged_.take_back(c);
      const auto worst = staged_.worst_error(c, tol_.rtol, tol_.atol);
      static constexpr const char* kComponents[] = {"px", "py", "pz", "vx", "vy", "vz"};
      culprit = ": body " + std::to_string(worst.body) + "'s " + kComponents[worst.component] + " has the largest error (" +
                shortest_text(worst.weighted) + " times its tolerance at the last step tried, " +
                shortest_text(double(last_size_)) + ")";
    } catch (const std::exception&) {  // user code threw: the underflow is still the error
    }
    throw Error(underflow_message(t, type_name<T>()) + culprit);
  }

  void reject(const StepContext<T>& c) {
    staged_.take_back(c);
    ++stats_.rejected;
    kept_scale_ = c.accel_scale;  // stage 0 was evaluated at the state kept
  }

  // 0.01 |y| / |f(y)| in the error norm's weights (Hairer and Wanner's first guess), from
  // stage 0's accelerations, which the first attempt then reuses.
  double first_step(double span) {
    const T probe = T(std::min(span, 1.0));
    core_.check_step_size(probe, core_.lowered().particle, true);
    const StepContext<T> c{bodies_, probe, core_.accel_scale(probe), core_.clock.time(), workers_, interrupt_};
    staged_.evaluate_first_stage(c);
    ++stats_.evaluations;
    kept_scale_ = c.accel_scale;
    const auto acc = staged_.first_stage();
    const ParticleSet<T>& b = bodies_;
    const T* x[3] = {b.px(), b.py(), b.pz()};
    const T* v[3] = {b.vx(), b.vy(), b.vz()};
    const auto squares = [&](double rtol, double atol) {
      double y2 = 0, f2 = 0;
      for (int d = 0; d < 3; ++d) {
        const std::size_t n = b.size();
        y2 += scaled_squares(x[d], x[d], 1, rtol, atol, n) + scaled_squares(v[d], v[d], 1, rtol, atol, n);
        f2 += scaled_squares(v[d], x[d], 1, rtol, atol, n) +
              scaled_squares(acc[d], v[d], 1 / double(c.accel_scale), rtol, atol, n);
      }
      return std::pair{y2, f2};
    };
    return starting_step(squares, 6.0 * double(std::max<std::size_t>(b.size(), 1)), tol_, span);
  }

  StepperCore<T>& core_;
  StagedPath<T>& staged_;
  const Workers& workers_;
  ParticleSet<T>& bodies_;
  const Tolerances& tol_;
  AdaptiveStats stats_;
  T kept_scale_ = 0;  // the acceleration scale stage 0's kept accelerations carry; 0: none
  T last_size_ = 0;  // of the last attempt
  const StopRequest* interrupt_ = nullptr;  // the call's, for the attempts to poll
  const AdaptiveEvents<T>& events_;
};

}  // namespace

template <class T>
std::uint32_t stage_inputs_digest(const ParticleSet<T>& b) {
  const std::size_t n = b.size();
  std::uint32_t crc = 0;
  for (const T* a : {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz(), b.inv_mass()}) crc = crc_of_array(a, n, crc);
  for (int d = 0; d < 3; ++d) crc = crc_of_array(b.applied_force_data(d), n, crc);
  for (int k = 0; k < BodyParameters<T>::kKinds; ++k) {
    crc = crc_of_array(b.parameters().data(BodyParameter(k)), n, crc);
  }
  return crc;
}

template <class T>
AdaptiveStats advance_adaptively(StepperCore<T>& core, const Workers& workers, ParticleSet<T>& bodies,
                                 double t_end, const Tolerances& tolerances, double max_step,
                                 AdaptiveContinuation& continuation, const CallStops& stops,
                                 const AdaptiveEvents<T>& events) {
  return AdaptiveRun<T>(core, workers, bodies, tolerances, events).to(t_end, max_step, continuation, stops);
}

namespace {

// An accepted rigid step's scan, from the attempt's start to the set (scanned_to_stop).
template <class T>
bool rigid_stops_at_event(StepperCore<T>& core, const Workers& workers, RigidBodySet<T>& bodies,
                          RigidBlockPath<T>& path, const typename RigidBlockPath<T>::Call& call,
                          const AdaptiveEvents<T>& events, const Clock<T>& start) {
  const std::array<const T*, 13> before = path.attempt_start();
  const double h = double(call.h);
  return scanned_to_stop(
      events, workers, before.data(), state_arrays(bodies).data.data(), bodies.padded_size(), core.clock, start, h,
      [&] { path.take_back(call, workers); },
      [&](const typename EventWatch<T>::Stop& stop) {
        events.watch->settle(workers, bodies, core.rigid_probe(), call.renormalize, before.data(), stop, start.time(), h);
      });
}

}  // namespace

// The rigid first step as the particles' (starting_step), the rates from the probe path's stage
// 0 (the bodies untouched), over the 13 components of every body.
template <class T>
double rigid_first_step(StepperCore<T>& core, const Workers& workers, RigidBodySet<T>& bodies, double t,
                        double span, const Tolerances& tol) {
  RigidBlockPath<T>& probe = core.rigid_probe();
  probe.reserve(bodies.padded_size());
  probe.evaluate_rates({bodies, T(1), core.options.renormalize_quaternions}, workers, t);
  const ParticleSet<T>& c = bodies.centers();
  const std::array<const T*, 13> y{c.px(), c.py(), c.pz(), c.vx(), c.vy(), c.vz(),
                                   bodies.q(0), bodies.q(1), bodies.q(2), bodies.q(3),
                                   bodies.l(0), bodies.l(1), bodies.l(2)};
  const auto squares = [&](double rtol, double atol) {
    double y2 = 0, f2 = 0;
    for (int c = 0; c < 13; ++c) {
      y2 += scaled_squares(y[c], y[c], 1, rtol, atol, bodies.size());
      f2 += scaled_squares(probe.rate_of(c), y[c], 1, rtol, atol, bodies.size());
    }
    return std::pair{y2, f2};
  };
  return starting_step(squares, 13.0 * double(std::max<std::size_t>(bodies.size(), 1)), tol, span);
}

template <class T>
AdaptiveStats advance_adaptively(StepperCore<T>& core, const Workers& workers, RigidBodySet<T>& bodies,
                                 double t_end, const Tolerances& tol, const AdaptiveEvents<T>& events) {
  RigidBlockPath<T>& path = *core.paths.rigid_block;
  if (path.coupled()) core.reach(bodies.centers());
  path.reserve(bodies.padded_size());
  const Method& method = core.method;
  StepController controller(std::min(method.order, method.embedded_order));
  AdaptiveStats stats;
  double t = core.clock.time();
  if (t_end == t) return stats;
  double h = tol.initial_step;
  if (!(h > 0)) h = rigid_first_step(core, workers, bodies, t, t_end - t, tol), ++stats.evaluations;
  while (t < t_end) {
    const auto [size, last] = next_attempt<T>(t, t_end, h, tol.max_step);
    if (underflows(t, size)) throw Error(underflow_message(t, type_name<T>()));
    core.begin(size, core.lowered().rigid, bodies.parameters(), true);
    const typename RigidBlockPath<T>::Call call{bodies, size, core.options.renormalize_quaternions};
    path.prepare(call);
    const double err = path.attempt(call, workers, t, tol.rtol, tol.atol);
    stats.evaluations += std::uint64_t(method.tableau.stages);
    const bool accepted = err <= 1;
    if (accepted) {
      const Clock<T> start = core.clock;
      ++core.clock.steps;
      if (last) core.clock.set(t_end);
      count_accepted(stats, double(size));
      if (events.watch && rigid_stops_at_event(core, workers, bodies, path, call, events, start)) break;
      t = core.clock.time();
    } else {
      path.take_back(call, workers);
      ++stats.rejected;
    }
    h = controller.next(double(size), err, accepted);
  }
  stats.next_step = h;
  return stats;
}

template std::uint32_t stage_inputs_digest(const ParticleSet<float>&);
template std::uint32_t stage_inputs_digest(const ParticleSet<double>&);
template AdaptiveStats advance_adaptively(StepperCore<float>&, const Workers&, RigidBodySet<float>&, double,
                                          const Tolerances&, const AdaptiveEvents<float>&);
template AdaptiveStats advance_adaptively(StepperCore<double>&, const Workers&, RigidBodySet<double>&, double,
                                          const Tolerances&, const AdaptiveEvents<double>&);
template AdaptiveStats advance_adaptively(StepperCore<float>&, const Workers&, ParticleSet<float>&, double,
                                          const Tolerances&, double, AdaptiveContinuation&, const CallStops&,
                                          const AdaptiveEvents<float>&);
template AdaptiveStats advance_adaptively(StepperCore<double>&, const Workers&, ParticleSet<double>&, double,
                                          const Tolerances&, double, AdaptiveContinuation&, const CallStops&,
                                          const AdaptiveEvents<double>&);

}  // namespace kinema
