#include "step/stepper_core.hpp"

#include "forces/force_lowering.hpp"
#include "kinema/error.hpp"
#include "step/step_checks.hpp"

namespace kinema {

template <class T>
StepperCore<T>::StepperCore(std::shared_ptr<const ForceModel<T>> f, const Method& m, const StepperOptions& o)
    : method(m), options(o) {
  validate(method);
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

template <class T>
void StepperCore<T>::check_step_size(T h, const kernels::LocalForces<T>& local) const {
  check_step_positive(h);
  check_scaled_forces(local, paths.lowered->coupled, accel_scale(h), h);
}

template <class T>
void StepperCore<T>::begin(T h, const kernels::LocalForces<T>& local, const BodyParameters<T>& own) {
  check_step_size(h, local);
  check_scaled_parameters(own, local, accel_scale(h), h);
  clock.use(h);
}

template <class T>
StepContext<T> StepperCore<T>::start(ParticleSet<T>& bodies, T h, const kernels::LocalForces<T>& local,
                                     const Workers& workers) {
  begin(h, local, bodies.parameters());
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
