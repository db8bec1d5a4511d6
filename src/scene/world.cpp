#include "kinema/world.hpp"

#include "kinema/diagnostics.hpp"
#include "kinema/error.hpp"

namespace kinema {

template <class T>
World<T>::World(const Scene& scene, const Method& method, StepperOptions options)
    : forces_(std::make_shared<const ForceModel<T>>(make_forces<T>(scene))),
      particles(make_particles<T>(scene)),
      rigid(make_rigid_bodies<T>(scene)),
      particle_stepper_(forces_, method, options),
      rigid_stepper_(forces_, method, options) {}

template <class T>
void World<T>::advance(T h, std::uint64_t steps) {
  if (particles.size() > 0) particle_stepper_.advance(particles, h, steps);
  if (rigid.size() > 0) rigid_stepper_.advance(rigid, h, steps);
}

template <class T>
double World<T>::time() const {
  return main_stepper().time();
}

template <class T>
double World<T>::total_energy() const {
  return (particles.size() > 0 ? energy(particles, *forces_).total() : 0) +
         (rigid.size() > 0 ? energy(rigid, *forces_).total() : 0);
}

template <class T>
AdaptiveStats World<T>::advance_to(double t_end, const Tolerances& tolerances) {
  if (rigid.size() > 0) throw Error("error-controlled steps are for particles; the scene has rigid bodies");
  return particle_stepper_.advance_to(particles, t_end, tolerances);
}

template <class T>
bool World<T>::finite() const {
  return all_finite(particles) && all_finite(rigid);
}

template class World<float>;
template class World<double>;

}  // namespace kinema
