#pragma once
// The bodies of a stress run, in groups: each group is one body set with its own force
// model and stepper, and says which quantities its physics conserves.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "kinema/scenes.hpp"

namespace kinema::cli {

template <class T>
class StressGroup {
 public:
  StressGroup(std::string name, ParticleSet<T> bodies, ForceModel<T> forces, const Method& method,
              const StepperOptions& options);
  StressGroup(std::string name, RigidBodySet<T> bodies, ForceModel<T> forces, const Method& method,
              const StepperOptions& options);

  const std::string& name() const { return name_; }
  bool rigid() const { return rigid_; }
  std::size_t size() const { return rigid_ ? rigid_bodies_.size() : particles_.size(); }
  const Stepper<T>& stepper() const { return stepper_; }
  // Energy is conserved without dissipative or non-potential terms; momentum without
  // forces from outside the group (coupled terms only).
  bool conserves_energy() const { return conserves_energy_; }
  bool conserves_momentum() const { return conserves_momentum_; }

  // Throws NonFiniteError under the check and clamp guards.
  void advance(T h, std::uint64_t steps);
  double energy() const;
  Vec3<double> momentum() const;
  double momentum_scale() const;  // sum of m |v|: what a momentum drift is measured against
  std::optional<NonFinite> first_non_finite() const;
  // The body arrays and the force model's spring pairs.
  std::size_t state_bytes() const;
  // Its set and stepper as a checkpoint's record, and back from record k (kinema::Error when
  // that record is not this group's kind, size, precision, method or model).
  void save(CheckpointWriter& out) const;
  void restore(const CheckpointReader& in, std::size_t k);

 private:
  std::string name_;
  bool rigid_;
  bool conserves_energy_, conserves_momentum_;  // read off the forces before the stepper takes them
  ParticleSet<T> particles_;
  RigidBodySet<T> rigid_bodies_;
  Stepper<T> stepper_;
};

// The built-in randomized scene of about `bodies` bodies (at least 1), the same for a seed
// on every machine: particles under every local term, a free spring network, an N-body
// cluster (at most 2048 bodies: a direct sum costs N^2), rigid bodies under every rotational
// term and torque-free rigid bodies in uniform gravity.
template <class T>
std::vector<StressGroup<T>> random_stress_groups(std::uint64_t bodies, std::uint64_t seed,
                                                 const Method& method, const StepperOptions& options);

// A scene's particles and rigid bodies, each a group.
template <class T>
std::vector<StressGroup<T>> scene_stress_groups(const Scene& scene, const Method& method,
                                                const StepperOptions& options);

// The built-in scene's step size.
inline constexpr double kStressDt = 1e-3;

}  // namespace kinema::cli
