#include "step/stepper_core.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "forces/force_lowering.hpp"
#include "kinema/error.hpp"
#include "step/step_checks.hpp"

namespace kinema {

namespace {

// The most a stage's or the step's weighted sum of rates adds up, in units of one rate:
// max(max_s sum_j |a_sj|, sum |b|, sum |b_hat|) (dopri5 about 25, rk4 1).
double weights_reach(const ButcherTableau& t) {
  double reach = 1;
  for (int s = 0; s < t.stages; ++s) {
    double row = 0;
    for (int j = 0; j < s; ++j) row += std::abs(t.a[s][j]);
    reach = std::max(reach, row);
  }
  double b = 0, b_hat = 0;
  for (int s = 0; s < t.stages; ++s) b += std::abs(t.b[s]), b_hat += std::abs(t.b_hat[s]);
  return std::max({reach, b, b_hat});
}

}  // namespace

template <class T>
StepperCore<T>::StepperCore(std::shared_ptr<const ForceModel<T>> f, const Method& m, const StepperOptions& o)
    : method(m), options(o) {
  validate(method);
  if (method.kind == MethodKind::runge_kutta) weights_reach_ = weights_reach(method.tableau);
  check_stepper_options<T>(options);
  table = &kernels::kernel_table<T>(options.isa, options.relaxed_fma);
  use(std::move(f));
}

template <class T>
void StepperCore<T>::use(std::shared_ptr<const ForceModel<T>> f) {
  if (!f) throw Error("stepper: null force model");
  const PathCapacity capacity{paths.particle_capacity(), paths.rigid_capacity()};
  StepPaths<T> fresh = build_paths(*f, method, *table, options, capacity);
  paths = std::move(fresh);
  forces_ = std::move(f);
}

template <class T>
T StepperCore<T>::accel_scale(T h) const {
  if (method.kind != MethodKind::runge_kutta) return 1;
  return T(kernels::acceleration_scale(method.tableau)) * h;
}


// h times the weights' reach, never past T's range (a force whose product with that still
// fits is no risk).
template <class T>
T StepperCore<T>::check_scale(T h, bool controlled) const {
  if (controlled || method.kind != MethodKind::runge_kutta) return accel_scale(h);
  const double reach = weights_reach_ * double(h);
  return std::max(accel_scale(h), T(std::min(reach, double(std::numeric_limits<T>::max()))));
}

template <class T>
void StepperCore<T>::check_step_size(T h, const kernels::LocalForces<T>& local, bool controlled) const {
  check_step_positive(h);
  check_scaled_forces(local, paths.lowered->coupled, check_scale(h, controlled), h);
}

template <class T>
void StepperCore<T>::begin(T h, const kernels::LocalForces<T>& local, const BodyParameters<T>& own, bool controlled) {
  check_step_size(h, local, controlled);
  check_scaled_parameters(own, local, check_scale(h, controlled), h);
  clock.use(h);
}

template <class T>
StepContext<T> StepperCore<T>::start(ParticleSet<T>& bodies, T h, const kernels::LocalForces<T>& local,
                                     const Workers& workers, bool controlled) {
  begin(h, local, bodies.parameters(), controlled);
  return {bodies, h, accel_scale(h), 0, workers};
}

template <class T>
StagedPath<T>& StepperCore<T>::acceleration_probe() {
  if (!paths.probe) {
    const LoweredForces<T>& l = *paths.lowered;
    paths.probe = std::make_unique<StagedPath<T>>(*forces_, euler, *table, l.particle, l.coupled);
  }
  return *paths.probe;
}

template <class T>
RigidBlockPath<T>& StepperCore<T>::rigid_probe() {
  if (!paths.rigid_probe) paths.rigid_probe = std::make_unique<RigidBlockPath<T>>(*forces_, euler, *table, *paths.lowered);
  return *paths.rigid_probe;
}

template <class T>
void StepperCore<T>::reach(const ParticleSet<T>& bodies) {
  check_reach(paths.lowered->coupled, bodies);
  paths.lowered->coupled.springs.lay_out();
}

template class StepperCore<float>;
template class StepperCore<double>;

}  // namespace kinema
