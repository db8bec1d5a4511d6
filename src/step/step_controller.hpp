#pragma once
// The step-size controller of the error-controlled driver (Stepper::advance_to).

#include <algorithm>
#include <cmath>

namespace kinema {

// A PI controller as Hairer and Wanner's DOPRI5 uses it: with k the lower order of the
// pair plus one, the next step is h / clamp(err^(1/k - 0.75 beta) / err_prev^beta / 0.9,
// 1/10, 5), beta = 0.2 / k: at most ten times longer, five times shorter. A rejected step
// shrinks by err^(1/k - 0.75 beta) / 0.9 (at most five times), and the step after a
// rejection does not grow.
class StepController {
 public:
  explicit StepController(int lower_order)
      : beta_(0.2 / (lower_order + 1)), exponent_(1.0 / (lower_order + 1) - 0.75 * beta_) {}

  // What it remembers between steps: a call stopped early goes on from it.
  struct State {
    double err_prev = 1e-4;
    bool rejected = false;
  };
  State state() const { return {err_prev_, rejected_}; }
  void set_state(const State& s) { err_prev_ = s.err_prev, rejected_ = s.rejected; }

  // The size to try after a step of size h whose error norm was `err` (accepted if <= 1).
  double next(double h, double err, bool accepted) {
    if (!std::isfinite(err)) {
      rejected_ = true;
      return h * kMinFactor;
    }
    const double proportional = std::pow(err, exponent_);
    if (!accepted) {
      rejected_ = true;
      return h / std::min(1 / kMinFactor, proportional / kSafety);
    }
    const double factor = std::clamp(proportional / std::pow(err_prev_, beta_) / kSafety,
                                     1 / kMaxFactor, 1 / kMinFactor);
    const double grown = h / factor;
    const double next = rejected_ ? std::min(grown, h) : grown;
    err_prev_ = std::max(err, 1e-4);
    rejected_ = false;
    return next;
  }

 private:
  static constexpr double kSafety = 0.9, kMinFactor = 0.2, kMaxFactor = 10;
  double beta_, exponent_;
  double err_prev_ = 1e-4;
  bool rejected_ = false;
};

}  // namespace kinema
