#pragma once
// The path a force model and a method take: the fused kernels (one pass per step, every
// stage in registers) when every term is local and the method built in, else the staged
// path (one pass per stage; without coupled terms, the block path: every stage of a block
// while it is in cache). Rigid bodies: fused, or the rigid block path (RigidCallbacks, user
// tableaus); they take no coupled terms.

#include <cstddef>
#include <memory>

#include "forces/force_lowering.hpp"
#include "kernels/kernels.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "step/block_path.hpp"
#include "step/rigid_block_path.hpp"
#include "step/staged_path.hpp"

namespace kinema {

template <class T>
struct StepPaths {
  std::unique_ptr<LoweredForces<T>> lowered;  // a fixed address: the staged paths keep references
  kernels::FusedFn<T> fused = nullptr;        // particles, when the fused path applies
  kernels::RigidFn<T> rigid = nullptr;        // rigid bodies, when the fused path applies
  std::unique_ptr<RigidBlockPath<T>> rigid_block;  // rigid bodies otherwise (no coupled terms)
  kernels::FusedFn<T> fused_applied = nullptr;  // the fused path for sets with applied forces

  kernels::FusedFn<T> fused_for(bool applied) const { return applied ? fused_applied : fused; }
  std::unique_ptr<BlockPath<T>> block;        // particles: callbacks, a built-in method, no coupling
  std::unique_ptr<StagedPath<T>> staged;      // particles otherwise
  std::unique_ptr<StagedPath<T>> probe;       // evaluates accelerations alone (made on demand)
};

// Lowers `forces` and picks their kernels. The staged path, if taken, keeps references to
// `forces`, `method` and `table`, and gets scratch for `staged_capacity` bodies. Throws
// kinema::Error for parameters that overflow T.
template <class T>
StepPaths<T> build_paths(const ForceModel<T>& forces, const Method& method, const kernels::KernelTable<T>& table,
                         bool force_staged, std::size_t staged_capacity);

}  // namespace kinema
