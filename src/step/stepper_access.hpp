#pragma once
// What a checkpoint reads and writes of a stepper beyond its public face: the continuation of
// an error-controlled call stopped early, and the staged path that keeps its first stage; and
// the stiffness estimate's accelerations, polling a stop request inside a coupled pass.

#include "kinema/stepper.hpp"
#include "step/adaptive_driver.hpp"
#include "step/staged_path.hpp"

namespace kinema {

template <class T>
struct StepperAccess {
  static AdaptiveContinuation& continuation(Stepper<T>& s);
  static const AdaptiveContinuation& continuation(const Stepper<T>& s);
  static StagedPath<T>* staged(const Stepper<T>& s);  // nullptr when the stepper has none
  // Stepper::accelerations, `stop` polled as Stepper::advance polls it (kinema::Stopped).
  static void accelerations(Stepper<T>& s, const ParticleSet<T>& bodies, double t, T* const out[3],
                            const StopRequest& stop);
  // The rates of rigid bodies' 13 state components at time t (RigidRatesFn).
  static void rigid_rates(Stepper<T>& s, const RigidBodySet<T>& bodies, double t, T* const out[13]);
};

extern template struct StepperAccess<float>;
extern template struct StepperAccess<double>;

}  // namespace kinema
