#pragma once
// World: what a scene builds, in one precision, ready to step. Its particles and rigid
// bodies (each set with its own stepper and clock), its forces, one job system.

#include <cstdint>
#include <memory>

#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "kinema/scene.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

template <class T>
class World {
 public:
  // With options.jobs null, the world owns a TbbJobSystem of options.threads threads that
  // both steppers share. Throws kinema::Error as the scene builders and Stepper do.
  World(const Scene& scene, const Method& method, StepperOptions options = {});
  World(World&&) noexcept = default;

  void advance(T h, std::uint64_t steps);
  double time() const;
  double total_energy() const;  // kinetic (with rotation) + potential, both sets
  bool finite() const;

  ParticleSet<T> particles;
  RigidBodySet<T> rigid;
  const ForceModel<T>& forces() const { return forces_; }
  const Stepper<T>& stepper() const { return particle_stepper_; }

 private:
  StepperOptions with_jobs(StepperOptions options);

  ForceModel<T> forces_;
  std::unique_ptr<JobSystem> owned_jobs_;
  Stepper<T> particle_stepper_, rigid_stepper_;
};

extern template class World<float>;
extern template class World<double>;

}  // namespace kinema
