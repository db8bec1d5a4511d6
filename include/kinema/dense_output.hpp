#pragma once
// Dense output: a body's state at any time inside a step, from the step's two ends.
//
// Every method gets the cubic Hermite of both ends: positions from (x0, v0, x1, v1),
// velocities from (v0, a0, v1, a1), a the accelerations the force model gives at each end.
// Its error inside a step is O(h^4) (exact for a trajectory of degree 2 or 3: a projectile
// under constant gravity), the order of rk4's own error, and below the error of the lower
// orders. Events (kinema/events.hpp) are located on it.

#include <array>
#include <algorithm>
#include <cstddef>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

// One body at both ends of a step of size h, in double.
struct StepEnds {
  double h = 0;
  std::array<double, 3> x0{}, v0{}, a0{}, x1{}, v1{}, a1{};
};

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
  return {w.of(e.x0[0], e.v0[0], e.x1[0], e.v1[0], e.h), w.of(e.x0[1], e.v0[1], e.x1[1], e.v1[1], e.h),
          w.of(e.x0[2], e.v0[2], e.x1[2], e.v1[2], e.h)};
}

inline std::array<double, 3> dense_velocity(const StepEnds& e, double theta) {
  const HermiteWeights w = HermiteWeights::at(theta);
  return {w.of(e.v0[0], e.a0[0], e.v1[0], e.a1[0], e.h), w.of(e.v0[1], e.a0[1], e.v1[1], e.a1[1], e.h),
          w.of(e.v0[2], e.a0[2], e.v1[2], e.a1[2], e.h)};
}

// The state of every body of a set at any time inside a step, for a caller that wants it
// (drawing between steps at the step's own accuracy, sampling at exact times):
//   dense.begin(stepper, bodies);   // before the step: x, v and the accelerations there
//   stepper.step(bodies, h);
//   dense.end(stepper, bodies);     // after it
//   dense.state_at(t, x, v);        // any t in [t0, t0 + h]
// Each begin and end evaluates the model once (Stepper::accelerations) and copies the state:
// a set that asks nothing of this pays nothing. Not for the inside of a frame's budget: the
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
  }
  void end(Stepper<T>& stepper, const ParticleSet<T>& bodies) {
    if (start_.x[0].size() != bodies.padded_size()) throw Error("DenseOutput::end: call begin on the same set first");
    t1_ = stepper.time();
    keep(stepper, bodies, end_);
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
    }
    return e;
  }
  // Every body at time t into x[0..2] and v[0..2] (the set's size each).
  void state_at(double t, T* const x[3], T* const v[3]) const {
    const double theta = fraction(t);
    const HermiteWeights w = HermiteWeights::at(theta);
    const double h = t1_ - t0_;
    for (std::size_t i = 0; i < size_; ++i) {
      for (int d = 0; d < 3; ++d) {
        x[d][i] = T(w.of(start_.x[d][i], start_.v[d][i], end_.x[d][i], end_.v[d][i], h));
        v[d][i] = T(w.of(start_.v[d][i], start_.a[d][i], end_.v[d][i], end_.a[d][i], h));
      }
    }
  }
  double fraction(double t) const {
    if (!ended_ || !(t >= t0_ && t <= t1_)) throw Error("DenseOutput: t must lie inside the last step, after end()");
    return t1_ > t0_ ? (t - t0_) / (t1_ - t0_) : 1;
  }

 private:
  struct End {
    std::array<AlignedArray<T>, 3> x, v, a;
  };
  void keep(Stepper<T>& stepper, const ParticleSet<T>& bodies, End& end) {
    const std::size_t n = bodies.padded_size();
    for (auto* arrays : {&end.x, &end.v, &end.a}) {
      for (auto& a : *arrays) {
        if (a.size() != n) a = AlignedArray<T>(n);
      }
    }
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

  End start_, end_;
  double t0_ = 0, t1_ = 0;
  std::size_t size_ = 0;
  bool ended_ = false;
};

}  // namespace kinema
