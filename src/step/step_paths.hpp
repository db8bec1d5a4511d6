#pragma once
// The path a force model and a method take: the fused kernels (one pass per step, every
// stage in registers) when every term is local and the method built in, else the staged
// path (one pass per stage; without coupled terms, the block path: every stage of a block
// while it is in cache). Rigid bodies: fused, or the rigid path (RigidCallbacks, point
// springs, coupled terms, user tableaus).

#include <cstddef>
#include <memory>

#include "forces/force_lowering.hpp"
#include "kernels/kernels.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "step/block_path.hpp"
#include "step/implicit_path.hpp"
#include "step/rigid_block_path.hpp"
#include "step/staged_path.hpp"

namespace kinema {

template <class T>
struct StepPaths {
  std::unique_ptr<LoweredForces<T>> lowered;  // a fixed address: the staged paths keep references
  kernels::FusedFn<T> fused = nullptr;        // particles, when the fused path applies
  kernels::FusedFn<T> fused_applied = nullptr;  // the same, for sets with applied forces
  std::unique_ptr<BlockPath<T>> block;        // particles: callbacks, a built-in method, no coupling
  std::unique_ptr<StagedPath<T>> staged;      // particles otherwise
  std::unique_ptr<StagedPath<T>> probe;       // evaluates accelerations alone (made on demand)
  std::unique_ptr<ImplicitPath<T>> implicit;  // particles under an implicit method
  kernels::RigidFn<T> rigid = nullptr;        // rigid bodies, when the fused path applies
  std::unique_ptr<RigidBlockPath<T>> rigid_block;  // rigid bodies otherwise
  std::unique_ptr<RigidBlockPath<T>> rigid_probe;  // evaluates rigid rates alone (made on demand)

  kernels::FusedFn<T> fused_for(bool applied) const { return applied ? fused_applied : fused; }
  // Bodies the particle paths' scratch holds, and the rigid block path's.
  std::size_t particle_capacity() const;
  std::size_t rigid_capacity() const { return rigid_block ? rigid_block->capacity() : 0; }
};

// Scratch to carry from old paths to new ones (Stepper::set_forces keeps it).
struct PathCapacity {
  std::size_t particles = 0, rigid = 0;
};

// Whether a rigid body's centre moves under the model's built-in local terms alone, as a
// particle would (no rigid callback, point spring, body spring or coupled term): then the
// fused rigid kernels apply (with a method that has them), and events can be located.
template <class T>
bool centres_move_alone(const ForceModel<T>& forces);

// Lowers `forces` and picks their kernels. The paths taken keep references to `forces`,
// `method` and `table`, and get scratch for `capacity` bodies. Throws kinema::Error for
// parameters that overflow T.
template <class T>
StepPaths<T> build_paths(const ForceModel<T>& forces, const Method& method, const kernels::KernelTable<T>& table,
                         const StepperOptions& options, PathCapacity capacity);

}  // namespace kinema
