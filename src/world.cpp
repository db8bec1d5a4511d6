#include "kinema/world.hpp"

#include "kinema/diagnostics.hpp"

namespace kinema {

template <class T>
World<T>::World(const Scene& scene, const Method& method, StepperOptions options)
    : particles(make_particles<T>(scene)),
      rigid(make_rigid_bodies<T>(scene)),
      forces_(make_forces<T>(scene)),
      particle_stepper_(forces_, method, with_jobs(options)),
      rigid_stepper_(forces_, method, with_jobs(options)) {}

template <class T>
StepperOptions World<T>::with_jobs(StepperOptions options) {
  if (options.jobs == nullptr) {
    if (!owned_jobs_) owned_jobs_ = std::make_unique<TbbJobSystem>(options.threads);
    options.jobs = owned_jobs_.get();
  }
  return options;
}

template <class T>
void World<T>::advance(T h, std::uint64_t steps) {
  if (particles.size() > 0) particle_stepper_.advance(particles, h, steps);
  if (rigid.size() > 0) rigid_stepper_.advance(rigid, h, steps);
}

template <class T>
double World<T>::time() const {
  return particles.size() > 0 ? particle_stepper_.time() : rigid_stepper_.time();
}

template <class T>
double World<T>::total_energy() const {
  return (particles.size() > 0 ? energy(particles, forces_).total() : 0) +
         (rigid.size() > 0 ? energy(rigid, forces_).total() : 0);
}

template <class T>
bool World<T>::finite() const {
  return all_finite(particles) && all_finite(rigid);
}

template class World<float>;
template class World<double>;

}  // namespace kinema
