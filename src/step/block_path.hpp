#pragma once
// The particle block path: a built-in method with callbacks and no coupled terms. A slice of
// a block runs each stage (or kick) with the fused kernels' arithmetic, the stage state in
// its block's scratch where the callbacks read it; a slice takes every step of a call while
// in cache (the driver, FixedSteps, runs the blocks).

#include <array>
#include <cstddef>

#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "parallel/blocks.hpp"
#include "step/step_context.hpp"

namespace kinema {

template <class T>
class BlockPath {
 public:
  // Keeps references: every argument must outlive the path. `builtin`: the method's index in
  // builtin_methods.
  BlockPath(const ForceModel<T>& forces, const Method& method, int builtin, const kernels::KernelTable<T>& table,
            const kernels::LocalForces<T>& local);

  void reserve(std::size_t padded);  // scratch for `padded` bodies; allocates only to grow
  std::size_t bytes() const;
  std::size_t capacity() const { return capacity_; }

  bool may_throw() const { return !forces_.callbacks().empty(); }
  // Builds the call's job (step size, where the arrays are): before any step_block.
  void prepare(const StepContext<T>& c);
  // Before a slice's steps of a call: its bodies' masses, as the callbacks' view gives them.
  void begin_slice(Block slice);
  // One step of one slice of a block (at most kernels::kSliceBodies<T> bodies) from time t0.
  void step_block(Block slice, double t0);
  void keep_block(Block b);     // saves the bodies' positions and velocities
  void restore_block(Block b);  // puts them back

 private:
  void runge_kutta_step(Block slice, T* scratch, double t0);
  void kick_drift_step(Block slice, T* scratch, double t0);
  void call_back(int s, Block slice, T* scratch, double t) const;
  kernels::SliceLayout layout() const;
  static T* at(T* scratch, std::size_t array);  // one array of a slice's scratch
  T* region(Block b);                            // its block's scratch: stage state, then masses

  const ForceModel<T>& forces_;
  const Method& method_;
  const kernels::KernelTable<T>& table_;
  const kernels::LocalForces<T>& local_;
  kernels::BlockStageFn<T> advance_fn_;
  kernels::BlockStepFn<T> kick_fn_;
  kernels::BlockJob<T> job_{};
  std::array<T, kMaxStages> op_steps_{};  // kick-drift: w h per operation
  std::size_t capacity_ = 0;
  // Per block, one slice's stage state and masses: the slices of a block take their steps
  // one after another in it, so it stays in the L1 cache. The callbacks' forces are zero between
  // phases: each kernel that reads them leaves zeros.
  AlignedArray<T> scratch_;
  std::size_t region_ = 0;  // elements of scratch_ per block
  std::array<AlignedArray<T>, 6> saved_;
};

extern template class BlockPath<float>;
extern template class BlockPath<double>;

}  // namespace kinema
