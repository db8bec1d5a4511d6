#pragma once
// Dense output: a body's state at any time inside a step, from the step's two ends.
//
// Every method gets the cubic Hermite of both ends: positions from (x0, v0, x1, v1),
// velocities from (v0, a0, v1, a1), a the accelerations the force model gives at each end.
// Its error inside a step is O(h^4) (exact for a trajectory of degree 2 or 3: a projectile
// under constant gravity), the order of rk4's own error, and below the error of the lower
// orders. Events (kinema/events.hpp) are located on it.

#include <array>

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

}  // namespace kinema
