#pragma once
// What one step or advance call works on, built on the caller's stack and handed to every
// phase and block task; the Stepper keeps only what lives across calls.

#include <cstddef>

#include "kernels/kernels.hpp"
#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "parallel/blocks.hpp"

namespace kinema {

// What a set's bodies carry besides their state, as the kernels take it.
template <class T>
kernels::PerBody<T> per_body(const ParticleSet<T>& b) {
  const BodyParameters<T>& p = b.parameters();
  return {{b.applied_force_data(0), b.applied_force_data(1), b.applied_force_data(2)},
          p.data(BodyParameter::gravity_factor),
          p.data(BodyParameter::linear_damping)};
}

// Whether the kernels read anything of the bodies' own (the fused particle path's plain
// variant reads none of it).
template <class T>
bool reads_per_body(const ParticleSet<T>& b) {
  return per_body(b).any();
}

// Each body's mass as a callback's view gives it: 1 / inv_mass, 0 where inv_mass is 0, as
// dynamic / (inv_mass + 1 - dynamic), dynamic 1 or 0: no division by zero (a host may trap
// it) and no branch, so the loop vectorizes.
template <class T>
void fill_masses(const T* inv_mass, T* mass, std::size_t count) {
  for (std::size_t i = 0; i < count; ++i) {
    const T dynamic = T(inv_mass[i] != T(0));
    mass[i] = dynamic / (inv_mass[i] + (T(1) - dynamic));
  }
}

// A set's arrays as the kernels take them.
template <class T>
kernels::BodyArrays<T> arrays(ParticleSet<T>& b) {
  return {{b.px(), b.py(), b.pz()}, {b.vx(), b.vy(), b.vz()}, b.inv_mass(), per_body(b)};
}

// The centres of mass of rigid bodies, likewise.
template <class T>
kernels::BodyArrays<T> center_arrays(RigidBodySet<T>& b) {
  return {{b.position_data(0), b.position_data(1), b.position_data(2)},
          {b.velocity_data(0), b.velocity_data(1), b.velocity_data(2)},
          b.centers().inv_mass(),
          per_body(b.centers())};
}

template <class T>
struct StepContext {
  ParticleSet<T>& bodies;  // particles, or the centres of rigid bodies
  T h;                     // step size
  T accel_scale;           // what stage accelerations are multiplied by (sigma h, or 1)
  double t0 = 0;           // time at the start of the step (staged path: callbacks see it)
  Workers workers{};       // where this call's blocks run
  // Polled before each block of a coupled pass (one N-body step can take seconds); true
  // abandons the step with kinema::Stopped, the bodies as before it. Null: never.
  const StopRequest* stop = nullptr;
};

}  // namespace kinema
