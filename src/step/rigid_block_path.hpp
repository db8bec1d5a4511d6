#pragma once
// The rigid block path: rigid bodies under RigidCallbacks (or a method without a fused
// kernel). Each stage (or kick) of a block writes the stage state where the callbacks read
// it, calls them, and turns what they add into the stage's rates; a block takes every step
// of a call while in cache (the driver, FixedSteps, runs the blocks). Weights are the
// method's, at run time: one set of kernels serves every method.

#include <array>
#include <cstddef>

#include "forces/force_lowering.hpp"
#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "parallel/blocks.hpp"

namespace kinema {

template <class T>
class RigidBlockPath {
 public:
  // Keeps references: every argument must outlive the path.
  RigidBlockPath(const ForceModel<T>& forces, const Method& method, const kernels::KernelTable<T>& table,
                 const LoweredForces<T>& lowered);

  // Scratch for `padded` bodies (a padded count); allocates only when it grows.
  void reserve(std::size_t padded);
  std::size_t bytes() const;
  std::size_t capacity() const { return capacity_; }

  // What one call steps: the set, the step size, whether q is renormalized after a step.
  struct Call {
    RigidBodySet<T>& bodies;
    T h;
    bool renormalize;
  };
  bool may_throw() const { return !forces_.rigid_callbacks().empty(); }
  // Builds the phases' jobs for the call: before any step_block.
  void prepare(const Call& call);
  // One step of one block from time t0.
  void step_block(const Call& call, Block b, double t0);
  // Keeps the block's state (save), or puts it back.
  void keep_block(const Call& call, Block b);
  void restore_block(const Call& call, Block b);

 private:
  kernels::RigidBlockJob<T> job(const Call& call);
  kernels::RigidBlockJob<T> with_terms(const kernels::RigidBlockJob<T>& base, const std::array<double, kMaxStages>& row,
                                       int count, T h, int s);
  void runge_kutta_step(Block b, double t0, T h);
  void kick_drift_step(Block b, double t0, T h);
  // A stage's state, the callbacks at time t, and the stage's rates.
  void evaluate(const kernels::RigidBlockJob<T>& job, Block b, double t);
  void combine(T* const out[3], const T* const rate[3], T step, Block b) const;
  RigidBlock<T> view(const kernels::RigidBlockJob<T>& job, Block b, double t) const;

  const ForceModel<T>& forces_;
  const Method& method_;
  const kernels::KernelTable<T>& table_;
  const LoweredForces<T>& lowered_;
  std::size_t capacity_ = 0;
  // Stage state (velocities per stage: they are the position rates), callback outputs, the
  // rates of each stage, and the state kept while user code may throw.
  std::array<AlignedArray<T>, 3> xs_, ls_, omega_, force_, torque_;
  std::array<AlignedArray<T>, 4> qs_;
  std::array<std::array<AlignedArray<T>, 3>, kMaxStages> vs_, kv_, kl_;
  std::array<std::array<AlignedArray<T>, 4>, kMaxStages> kq_;
  std::array<AlignedArray<T>, 13> saved_;
  // The call's jobs (prepare): per stage, the finish; per kick-drift operation, its step
  // (w h) and its turn.
  std::array<kernels::RigidBlockJob<T>, kMaxStages> stage_jobs_{}, turn_jobs_{};
  kernels::RigidBlockJob<T> finish_job_{};
  std::array<T, kMaxStages> op_steps_{};
};

extern template class RigidBlockPath<float>;
extern template class RigidBlockPath<double>;

}  // namespace kinema
