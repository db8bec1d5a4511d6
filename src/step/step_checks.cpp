#include "step/step_checks.hpp"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <string>
#include <utility>

#include "core/text.hpp"
#include "kinema/error.hpp"

namespace kinema {

template <class T>
void check_step_positive(T h) {
  if (!(std::isfinite(h) && h > 0)) {
    throw Error("step size h must be positive and finite in " + type_name<T>() + ", got " + shortest_text(h));
  }
}

template <class T>
void check_reach(const CoupledForces<T>& coupled, const ParticleSet<T>& bodies) {
  check_springs_reach(coupled.springs.covered, bodies.size());
}

template <class T>
void check_stepper_options(const StepperOptions& o) {
  check_named("stepper options: isa", o.isa, Isa::avx512);
  check_named("stepper options: guard", o.guard, FiniteGuard::clamp);
  check_named("stepper options: workers", o.workers, WorkerChoice::all);
  check_named("stepper options: implicit_preconditioner", o.implicit_preconditioner, ImplicitPreconditioner::multigrid);
  if (!(o.implicit_tolerance >= 0 && o.implicit_tolerance < 1)) {
    throw Error("stepper options: implicit_tolerance must be in [0, 1), got " + shortest_text(o.implicit_tolerance));
  }
  if (o.implicit_max_iterations < 1) {
    throw Error("stepper options: implicit_max_iterations must be >= 1, got " + std::to_string(o.implicit_max_iterations));
  }
  if (o.guard != FiniteGuard::clamp) return;
  for (const auto& [name, value] : {std::pair{"max_speed", o.max_speed},
                                    std::pair{"max_angular_speed", o.max_angular_speed}}) {
    // In T, and its square: the clamp compares squared speeds (one that rounds to 0 or whose
    // square underflows would stop every body, one whose square overflows would clamp none).
    const T square = T(value) * T(value);
    if (!(value > 0 && std::isfinite(square) && square >= std::numeric_limits<T>::min())) {
      throw Error(std::string("stepper options: ") + name + " must be > 0 with its square finite and normal in " +
                  type_name<T>() + ", got " + shortest_text(value));
    }
  }
}

void check_adaptive(const Method& method, double t_end, const Tolerances& tol, double now) {
  if (method.embedded_order == 0) {
    throw Error("advance_to needs a method with an embedded pair (bs3, dopri5); " + std::string(method.name) +
                " has none");
  }
  const auto nonnegative = [](double x) { return std::isfinite(x) && x >= 0; };
  if (!nonnegative(tol.rtol) || !nonnegative(tol.atol) || (tol.rtol == 0 && tol.atol == 0)) {
    throw Error("tolerances: rtol and atol must be finite and >= 0, not both 0; got rtol " +
                shortest_text(tol.rtol) + ", atol " + shortest_text(tol.atol));
  }
  if (!nonnegative(tol.initial_step) || !(tol.max_step > 0)) {
    throw Error("tolerances: initial_step must be finite and >= 0, max_step > 0");
  }
  if (!std::isfinite(t_end) || t_end < now) {
    throw Error("advance_to: t_end " + shortest_text(t_end) + " must be finite and not before time() = " +
                shortest_text(now));
  }
}

namespace {

template <class T>
double largest_of(std::initializer_list<const T*> arrays, std::size_t n) {
  double largest = 0;
  for (const T* a : arrays) {
    for (std::size_t i = 0; i < n; ++i) largest = std::max(largest, double(std::abs(a[i])));
  }
  return largest;
}

// Refuses tolerances under a sixteenth of an ulp of `scale`, which `what` names.
template <class T>
void check_floor(const Tolerances& tol, double scale, const char* what) {
  const double floor = double(std::numeric_limits<T>::epsilon()) / 16 * scale;
  if (tol.atol + tol.rtol * scale >= floor) return;
  throw Error("advance_to: rtol " + shortest_text(tol.rtol) + " and atol " + shortest_text(tol.atol) +
              " are far below the round-off of one step in " + type_name<T>() + " on these bodies (under " +
              shortest_text(floor, 2) + ", a sixteenth of an ulp of their largest " + what + "): no step can meet them");
}

}  // namespace

// The floor sits well under the round-off: error estimates may be met below it (auto's float
// pilots run at rtol 1e-7), but not at a sixteenth of an ulp, where the step only shrinks
// (rtol 1e-24 in double took 215 million steps, 1e-30 never ended).
template <class T>
void check_tolerance_floor(const ParticleSet<T>& bodies, const Tolerances& tol) {
  if (tol.rtol >= double(std::numeric_limits<T>::epsilon()) / 16) return;  // above the floor at any scale
  const std::size_t n = bodies.size();
  const double scale = largest_of({bodies.px(), bodies.py(), bodies.pz()}, n) +
                       largest_of({bodies.vx(), bodies.vy(), bodies.vz()}, n);
  check_floor<T>(tol, scale, "|x| + |v|");
}

// The error norm holds the orientations and angular momenta too: a body at rest at the
// origin still turns, its quaternion's components up to 1.
template <class T>
void check_tolerance_floor(const RigidBodySet<T>& bodies, const Tolerances& tol) {
  if (tol.rtol >= double(std::numeric_limits<T>::epsilon()) / 16) return;
  check_tolerance_floor(bodies.centers(), tol);
  const std::size_t n = bodies.size();
  const double scale = largest_of({bodies.q(0), bodies.q(1), bodies.q(2), bodies.q(3)}, n) +
                       largest_of({bodies.l(0), bodies.l(1), bodies.l(2)}, n);
  check_floor<T>(tol, scale, "|q| + |L|");
}

#define KINEMA_STEP_CHECKS(T)                                                                                   \
  template void check_tolerance_floor(const ParticleSet<T>&, const Tolerances&);                               \
  template void check_tolerance_floor(const RigidBodySet<T>&, const Tolerances&);                              \
  template void check_step_positive(T);                                                                         \
  template void check_reach(const CoupledForces<T>&, const ParticleSet<T>&);                                    \
  template void check_stepper_options<T>(const StepperOptions&);
KINEMA_STEP_CHECKS(float)
KINEMA_STEP_CHECKS(double)
#undef KINEMA_STEP_CHECKS

}  // namespace kinema
