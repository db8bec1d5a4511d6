#pragma once
// Dense output: a body's state at any time inside a step, from the step's two ends.
//
// Every method gets the cubic Hermite of both ends: positions from (x0, v0, x1, v1),
// velocities from (v0, a0, v1, a1), a the accelerations the force model gives at each end.
// Its error inside a step is O(h^4) (exact for a trajectory of degree 2 or 3: a projectile
// under constant gravity), the order of rk4's own error, and below the error of the lower
// orders. It is bs3's own interpolant (bs3 evaluates the model at both ends anyway). dopri5
// adds its own term of order 4 (Shampine's, from the step's seven stages, taken again for
// the bodies asked about): the Hermite plus (theta (1 - theta))^2 h sum_i d_i k_i. Events
// (kinema/events.hpp) are located on these.

#include <array>
#include <cmath>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <string>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

// One body at both ends of a step of size h, in double; rx and rv: dopri5's own term
// h sum_i d_i k_i for positions and velocities (zero for every other method).
struct StepEnds {
  double h = 0;
  std::array<double, 3> x0{}, v0{}, a0{}, x1{}, v1{}, a1{};
  std::array<double, 3> rx{}, rv{};
};

// dopri5's dense output weights d_i (Shampine 1986, as Hairer and Wanner give them).
inline constexpr std::array<double, 7> kDopri5Dense = {
    -12715105075.0 / 11282082432.0, 0, 87487479700.0 / 32700410799.0, -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0, -1453857185.0 / 822651844.0, 69997945.0 / 29380423.0};

// Whether a method is dopri5 (its tableau), whose steps have the interpolant above.
inline bool has_dopri5_interpolant(const Method& m) {
  return m.kind == MethodKind::runge_kutta && m.tableau.a == dopri5.tableau.a && m.tableau.b == dopri5.tableau.b;
}

// The weight of dopri5's own term at theta.
inline double dopri5_weight(double theta) {
  const double w = theta * (1 - theta);
  return w * w;
}

// The cubic Hermite weights at theta in [0, 1] (the fraction of the step).
struct HermiteWeights {
  double start, start_rate, end, end_rate;  // of y0, h y0', y1, h y1'

  static HermiteWeights at(double theta) {
    const double u = 1 - theta;
    return {(1 + 2 * theta) * u * u, theta * u * u, theta * theta * (3 - 2 * theta), theta * theta * (theta - 1)};
  }
  double of(double y0, double rate0, double y1, double rate1, double h) const {
    return start * y0 + start_rate * h * rate0 + end * y1 + end_rate * h * rate1;
  }
};

inline std::array<double, 3> dense_position(const StepEnds& e, double theta) {
  const HermiteWeights w = HermiteWeights::at(theta);
  const double r = dopri5_weight(theta);
  std::array<double, 3> x;
  for (int d = 0; d < 3; ++d) x[d] = w.of(e.x0[d], e.v0[d], e.x1[d], e.v1[d], e.h) + r * e.rx[d];
  return x;
}

inline std::array<double, 3> dense_velocity(const StepEnds& e, double theta) {
  const HermiteWeights w = HermiteWeights::at(theta);
  const double r = dopri5_weight(theta);
  std::array<double, 3> v;
  for (int d = 0; d < 3; ++d) v[d] = w.of(e.v0[d], e.a0[d], e.v1[d], e.a1[d], e.h) + r * e.rv[d];
  return v;
}

namespace detail {

// What end() refuses of the begin() it closes: none, another number of bodies, more than one
// step of one size since (the interpolant spans one step; a stop event may end it early), or
// a clock that ends more than its last step past begin's time (moved by set_time or
// set_clock, or several steps of advance_to or before a stop event).
struct DenseSpan {
  StepperClock start;
  std::size_t bodies = 0;
  bool begun = false;

  void check_end(const char* who, const StepperClock& now, std::size_t bodies_now) const {
    if (!begun) throw Error(std::string(who) + "::end: call begin on the same set first");
    if (bodies_now != bodies) {
      throw Error(std::string(who) + "::end: the set has " + std::to_string(bodies_now) + " bodies, " +
                  std::to_string(bodies) + " at begin");
    }
    // Counted on from begin's clock, or from its time where a new size moved the origin there.
    const double begin_time = start.origin + double(start.steps) * start.h;
    const bool same_count = now.origin == start.origin && now.h == start.h;
    if (same_count && now.steps < start.steps) throw Error(std::string(who) + "::end: the clock was set back since begin");
    // Elsewhere the clock ends within its last step of begin's time (a stop event or
    // advance_to's last step sets it there; h in T: float's rounding allowed), or the span is
    // not one step and would be drawn wrong.
    const double span = now.origin + double(now.steps) * now.h - begin_time;
    if (!same_count && now.origin != begin_time && !(span >= 0 && span <= now.h * (1 + 1e-6))) {
      throw Error(std::string(who) + "::end: the clock ends more than one step past begin (set_time or set_clock "
                                     "moved it, or several steps were taken); begin and end bracket one step");
    }
    const bool counted_on = same_count;
    const std::uint64_t since = counted_on ? now.steps - start.steps : now.origin == begin_time ? now.steps : 0;
    if (since > 1) {
      throw Error(std::string(who) + "::end: " + std::to_string(since) +
                  " steps since begin; begin and end bracket one step");
    }
  }
};

}  // namespace detail

// The fraction of the step [t0, t1] at t, which may lie up to 4 ulps of the ends' magnitude
// outside it (an event hit's time, t0 + theta h, can round past the clock's end of the step):
// kinema::Error beyond that, or before end() (`who` names the caller).
inline double step_fraction(double t, double t0, double t1, bool ended, const char* who) {
  const double slack = 4 * std::numeric_limits<double>::epsilon() * std::max(std::abs(t0), std::abs(t1));
  if (!ended || !(t >= t0 - slack && t <= t1 + slack)) {
    throw Error(std::string(who) + ": t must lie inside the last step, after end()");
  }
  return t1 > t0 ? std::clamp((t - t0) / (t1 - t0), 0.0, 1.0) : 1;
}

// The state of every body of a set at any time inside a step, for a caller that wants it
// (drawing between steps at the step's own accuracy, sampling at exact times):
//   dense.begin(stepper, bodies);   // before the step: x, v and the accelerations there
//   stepper.step(bodies, h);
//   dense.end(stepper, bodies);     // after it
//   dense.state_at(t, x, v);        // any t in [t0, t0 + h] (to 4 ulps: a hit's time)
// Each begin and end evaluates the model once (Stepper::accelerations) and copies the state;
// after a dopri5 step, end also takes the step's five inner stages again (five more
// evaluations, on a copy of the set) for dopri5's own interpolant. A set that asks nothing
// of this pays nothing. Not for the inside of a frame's budget: the
// first call allocates. Forces applied to single bodies are cleared by the step (unless the
// set keeps them, ParticleSet::keep_forces), so end() would not see them: keep them over a
// step that dense output spans.
template <class T>
class DenseOutput {
 public:
  void begin(Stepper<T>& stepper, const ParticleSet<T>& bodies) {
    t0_ = stepper.time();
    keep(stepper, bodies, start_);
    ended_ = false;
    span_ = {stepper.clock(), bodies.size(), true};
  }
  void end(Stepper<T>& stepper, const ParticleSet<T>& bodies) {
    span_.check_end("DenseOutput", stepper.clock(), bodies.size());
    t1_ = stepper.time();
    keep(stepper, bodies, end_);
    own_ = has_dopri5_interpolant(stepper.method());
    if (own_) dopri5_terms(stepper, bodies);
    ended_ = true;
  }
  double start_time() const { return t0_; }
  double end_time() const { return t1_; }
  // Body i at both ends of the step (after end(); i below the set's size).
  StepEnds ends(std::size_t i) const {
    StepEnds e;
    e.h = t1_ - t0_;
    for (int d = 0; d < 3; ++d) {
      e.x0[d] = start_.x[d][i], e.v0[d] = start_.v[d][i], e.a0[d] = start_.a[d][i];
      e.x1[d] = end_.x[d][i], e.v1[d] = end_.v[d][i], e.a1[d] = end_.a[d][i];
      if (own_) e.rx[d] = rx_[d][i], e.rv[d] = rv_[d][i];
    }
    return e;
  }
  // Every body at time t into x[0..2] and v[0..2] (the set's size each).
  void state_at(double t, T* const x[3], T* const v[3]) const {
    const double theta = fraction(t);
    const HermiteWeights w = HermiteWeights::at(theta);
    const double h = t1_ - t0_, r = dopri5_weight(theta);
    for (std::size_t i = 0; i < size_; ++i) {
      for (int d = 0; d < 3; ++d) {
        double xi = w.of(start_.x[d][i], start_.v[d][i], end_.x[d][i], end_.v[d][i], h);
        double vi = w.of(start_.v[d][i], start_.a[d][i], end_.v[d][i], end_.a[d][i], h);
        if (own_) xi += r * rx_[d][i], vi += r * rv_[d][i];
        x[d][i] = T(xi), v[d][i] = T(vi);
      }
    }
  }
  double fraction(double t) const { return step_fraction(t, t0_, t1_, ended_, "DenseOutput"); }

 private:
  struct End {
    std::array<AlignedArray<T>, 3> x, v, a;
  };
  void keep(Stepper<T>& stepper, const ParticleSet<T>& bodies, End& end) {
    const std::size_t n = bodies.padded_size();
    resize(n, {&end.x, &end.v, &end.a});
    const T* x[3] = {bodies.px(), bodies.py(), bodies.pz()};
    const T* v[3] = {bodies.vx(), bodies.vy(), bodies.vz()};
    for (int d = 0; d < 3; ++d) {
      std::copy(x[d], x[d] + n, end.x[d].data());
      std::copy(v[d], v[d] + n, end.v[d].data());
    }
    T* const a[3] = {end.a[0].data(), end.a[1].data(), end.a[2].data()};
    stepper.accelerations(bodies, stepper.time(), a);
    size_ = bodies.size();
  }

  // dopri5's k_j (the stage velocities and accelerations) for the inner stages j = 1 .. 5,
  // each stage's state formed in double from the step's start, then its term
  // h sum_j d_j k_j (k_0 and k_6 are the ends').
  void dopri5_terms(Stepper<T>& stepper, const ParticleSet<T>& bodies) {
    const std::size_t n = bodies.padded_size();
    const ButcherTableau& tab = dopri5.tableau;
    const double h = t1_ - t0_;
    stages_ = bodies;
    resize(n, {&rx_, &rv_});
    for (auto& k : inner_) resize(n, {&k.v, &k.a});
    const auto k_x = [&](int j, int d) { return j == 0 ? start_.v[d].data() : inner_[j - 1].v[d].data(); };
    const auto k_v = [&](int j, int d) { return j == 0 ? start_.a[d].data() : inner_[j - 1].a[d].data(); };
    T* const state[6] = {stages_.px(), stages_.py(), stages_.pz(), stages_.vx(), stages_.vy(), stages_.vz()};
    for (int s = 1; s < 6; ++s) {
      for (int d = 0; d < 3; ++d) {
        for (std::size_t i = 0; i < n; ++i) {
          double x = start_.x[d][i], v = start_.v[d][i];
          for (int j = 0; j < s; ++j) x += h * tab.a[s][j] * k_x(j, d)[i], v += h * tab.a[s][j] * k_v(j, d)[i];
          state[d][i] = T(x), state[3 + d][i] = T(v);
          inner_[s - 1].v[d][i] = T(v);
        }
      }
      T* const a[3] = {inner_[s - 1].a[0].data(), inner_[s - 1].a[1].data(), inner_[s - 1].a[2].data()};
      stepper.accelerations(stages_, t0_ + tab.c[s] * h, a);
    }
    for (int d = 0; d < 3; ++d) {
      for (std::size_t i = 0; i < n; ++i) {
        double rx = kDopri5Dense[6] * end_.v[d][i], rv = kDopri5Dense[6] * end_.a[d][i];
        for (int j = 0; j < 6; ++j) rx += kDopri5Dense[j] * k_x(j, d)[i], rv += kDopri5Dense[j] * k_v(j, d)[i];
        rx_[d][i] = h * rx, rv_[d][i] = h * rv;
      }
    }
  }
  static void resize(std::size_t n, std::initializer_list<std::array<AlignedArray<T>, 3>*> arrays) {
    for (auto* three : arrays) {
      for (auto& a : *three) {
        if (a.size() != n) a = AlignedArray<T>(n);
      }
    }
  }

  End start_, end_;
  struct Stage {
    std::array<AlignedArray<T>, 3> v, a;
  };
  std::array<Stage, 5> inner_;
  std::array<AlignedArray<T>, 3> rx_, rv_;
  ParticleSet<T> stages_;
  double t0_ = 0, t1_ = 0;
  std::size_t size_ = 0;
  bool ended_ = false, own_ = false;
  detail::DenseSpan span_;
};

// Dense output of rigid bodies: each of the 13 state components (centre x, v; orientation q;
// angular momentum L) on the cubic Hermite of its values and rates (Stepper::rates) at both
// ends, the orientation normalized after (a unit quaternion at every t; the Hermite's error
// is O(h^4) before and after). Used as DenseOutput is; every method gets the Hermite.
template <class T>
class RigidDenseOutput {
 public:
  static constexpr int kComponents = 13;
  void begin(Stepper<T>& stepper, const RigidBodySet<T>& bodies) {
    t0_ = stepper.time();
    keep(stepper, bodies, start_);
    ended_ = false;
    span_ = {stepper.clock(), bodies.size(), true};
  }
  void end(Stepper<T>& stepper, const RigidBodySet<T>& bodies) {
    span_.check_end("RigidDenseOutput", stepper.clock(), bodies.size());
    t1_ = stepper.time();
    keep(stepper, bodies, end_);
    ended_ = true;
  }
  double start_time() const { return t0_; }
  double end_time() const { return t1_; }
  // Every body at time t: x, v, L into three arrays each, q into four (w x y z), the set's
  // size each.
  void state_at(double t, T* const x[3], T* const v[3], T* const q[4], T* const l[3]) const {
    const double theta = step_fraction(t, t0_, t1_, ended_, "RigidDenseOutput"), h = t1_ - t0_;
    const HermiteWeights w = HermiteWeights::at(theta);
    T* const out[kComponents] = {x[0], x[1], x[2], v[0], v[1], v[2], q[0], q[1], q[2], q[3], l[0], l[1], l[2]};
    for (std::size_t i = 0; i < size_; ++i) {
      double y[kComponents];
      for (int c = 0; c < kComponents; ++c) {
        y[c] = w.of(start_.y[c][i], start_.rate[c][i], end_.y[c][i], end_.rate[c][i], h);
      }
      const double norm = std::sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9]);
      for (int c = 6; c < 10; ++c) y[c] /= norm;
      for (int c = 0; c < kComponents; ++c) out[c][i] = T(y[c]);
    }
  }

 private:
  struct End {
    std::array<AlignedArray<T>, kComponents> y, rate;
  };
  void keep(Stepper<T>& stepper, const RigidBodySet<T>& bodies, End& end) {
    const std::size_t n = bodies.padded_size();
    for (auto* arrays : {&end.y, &end.rate}) {
      for (auto& a : *arrays) {
        if (a.size() != n) a = AlignedArray<T>(n);
      }
    }
    const ParticleSet<T>& c = bodies.centers();
    const T* const y[kComponents] = {c.px(), c.py(), c.pz(), c.vx(), c.vy(), c.vz(), bodies.q(0),
                                     bodies.q(1), bodies.q(2), bodies.q(3), bodies.l(0), bodies.l(1), bodies.l(2)};
    T* rate[kComponents];
    for (int k = 0; k < kComponents; ++k) {
      std::copy(y[k], y[k] + n, end.y[k].data());
      rate[k] = end.rate[k].data();
    }
    stepper.rates(bodies, stepper.time(), rate);
    size_ = bodies.size();
  }

  End start_, end_;
  double t0_ = 0, t1_ = 0;
  std::size_t size_ = 0;
  bool ended_ = false;
  detail::DenseSpan span_;
};

}  // namespace kinema
