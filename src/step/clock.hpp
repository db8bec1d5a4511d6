#pragma once
// A stepper's simulated time.

#include <cstdint>

namespace kinema {

// Simulated time as origin + steps x h: no running sum, so step k sees exactly t0 + k h.
template <class T>
struct Clock {
  double origin = 0;
  std::uint64_t steps = 0;
  T h = 0;

  double time() const { return origin + double(steps) * double(h); }
  // A new step size moves the origin to now.
  void use(T step_size) {
    if (step_size == h) return;
    origin = time();
    steps = 0;
    h = step_size;
  }
  void set(double t) { origin = t, steps = 0; }
};

}  // namespace kinema
