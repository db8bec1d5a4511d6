#pragma once
// What a stepper keeps across calls, shared by its fixed-step and adaptive drivers: the
// force model and the paths it takes, the method, the options, the clock.

#include <memory>

#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "kinema/stepper.hpp"
#include "parallel/blocks.hpp"
#include "step/clock.hpp"
#include "step/step_context.hpp"
#include "step/step_paths.hpp"

namespace kinema {

template <class T>
class StepperCore {
 public:
  // Throws kinema::Error for an invalid method, options or model, or an unavailable ISA.
  StepperCore(std::shared_ptr<const ForceModel<T>> forces, const Method& method, const StepperOptions& options);
  StepperCore(const StepperCore&) = delete;  // the paths keep references to the members
  StepperCore& operator=(const StepperCore&) = delete;

  // Takes a new model. Everything it needs is built first (lowering, kernels, scratch as
  // large as the last), so whatever throws leaves the core as it was.
  void use(std::shared_ptr<const ForceModel<T>> forces);

  // What the stage accelerations are multiplied by: sigma h for Runge-Kutta methods (see
  // kernels::acceleration_scale), 1 for kicks, which scale by their own weight.
  T accel_scale(T h) const;
  // What the step size checks scale the forces by: h times the most a stage's sum of rates
  // adds up to, so that a step whose sums would overflow is refused. Controlled (error
  // control, whose steps are not the caller's to choose, rejects and shrinks such a step):
  // accel_scale alone.
  T check_scale(T h, bool controlled) const;
  // Throws what a step of size h would throw to a set feeling `local` (the particles' or the
  // rigid bodies' terms, which add the point forces' push).
  void check_step_size(T h, const kernels::LocalForces<T>& local, bool controlled = false) const;
  // Starts a call of steps of size h for a set whose own parameters are `own`: checks h (and
  // the parameters' overflow with it), and a new h moves the clock's origin to now.
  void begin(T h, const kernels::LocalForces<T>& local, const BodyParameters<T>& own, bool controlled = false);
  // begin(), and the call's context.
  StepContext<T> start(ParticleSet<T>& bodies, T h, const kernels::LocalForces<T>& local, const Workers& workers,
                       bool controlled = false);
  // The staged path that evaluates accelerations alone (Euler's first stage), made at the
  // first call and kept until the model changes.
  StagedPath<T>& acceleration_probe();
  // The same for rigid bodies: the rigid path under Euler, whose stage 0 gives the rates.
  RigidBlockPath<T>& rigid_probe();

  const ForceModel<T>& forces() const { return *forces_; }
  const LoweredForces<T>& lowered() const { return *paths.lowered; }
  // Refuses a set that lacks bodies the springs join (kinema::Error), then lays the
  // network out if no set has yet: before any step, acceleration or estimate on `bodies`.
  void reach(const ParticleSet<T>& bodies);

  Method method;
  StepperOptions options;
  const kernels::KernelTable<T>* table = nullptr;

 private:
  double weights_reach_ = 1;  // the method's, for check_scale: computed once
  // Before the paths, which refer to it: destroyed after them.
  std::shared_ptr<const ForceModel<T>> forces_;

 public:
  StepPaths<T> paths;
  Clock<T> clock;
};

extern template class StepperCore<float>;
extern template class StepperCore<double>;

}  // namespace kinema
