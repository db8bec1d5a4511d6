#pragma once
// The rigid path: rigid bodies under RigidCallbacks, point springs or coupled terms, or a
// method without a fused kernel. Each stage (or kick) of a block writes the stage state where
// the callbacks read it, adds the point springs', body springs', coupled terms' and
// callbacks' forces and torques, and turns them into the stage's rates (N-body gravity adds
// to them). Without coupled terms a block takes every step of a call while in cache (the
// driver, FixedSteps, runs the blocks); with them each phase is a pass over every block
// (step_all), since they read every body's stage state. Weights are the method's, at run
// time: one set of kernels serves every method.

#include <array>
#include <cstddef>
#include <vector>

#include "forces/force_lowering.hpp"
#include "forces/rigid_coupling.hpp"
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
  // User code runs in a step (a callback or a CoupledTerm).
  bool may_throw() const { return !forces_.rigid_callbacks().empty() || !forces_.coupled_terms().empty(); }
  // Coupled terms: each phase is a pass over every block (step_all), not step_block.
  bool coupled() const { return forces_.couples_rigid(); }
  // Builds the phases' jobs for the call: before any step. Throws kinema::Error when a spring
  // joins a body the set lacks.
  void prepare(const Call& call);
  // One step of one block from time t0 (no coupled terms).
  void step_block(const Call& call, Block b, double t0);
  // One step of every block from time t0, each phase a pass on `workers` (N-body gravity's on
  // all of them), polling `stop` (may be null) before each block of a pass of N-body gravity
  // or user code. When anything throws, the bodies are put back as they were.
  void step_all(const Call& call, const Workers& workers, double t0, const StopRequest* stop);
  // Keeps the block's state (save), or puts it back.
  void keep_block(const Call& call, Block b);
  void restore_block(const Call& call, Block b);

  // Error control, for a Runge-Kutta method with an embedded pair: one step from t0 that can
  // be taken back, and its error estimate's weighted RMS norm over every body's 13 state
  // components (x, v, q, L), each weighted by atol + rtol max(|y0|, |y1|) (Tolerances); the
  // blocks' sums added in block order, so the norm does not depend on threads. Whatever
  // throws leaves the bodies as they were.
  double attempt(const Call& call, const Workers& workers, double t0, double rtol, double atol);
  void take_back(const Call& call, const Workers& workers);
  // Where the last attempt started: its 13 state arrays (x, v, q, L), kept until the next.
  std::array<const T*, 13> attempt_start() const {
    std::array<const T*, 13> start;
    for (int a = 0; a < 13; ++a) start[a] = saved_[a].data();
    return start;
  }

  // The rates of every state component (x, v, q, L: 13 arrays, padded) at the bodies' state
  // and time t: stage 0 alone, the bodies untouched. For the stiffness estimate.
  void evaluate_rates(const Call& call, const Workers& workers, double t);
  const T* rate_of(int component) const { return rate(component, 0); }

 private:
  kernels::RigidBlockJob<T> job(const Call& call);
  kernels::RigidBlockJob<T> with_terms(const kernels::RigidBlockJob<T>& base, const std::array<double, kMaxStages>& row,
                                       int count, T h, int s);
  void runge_kutta_step(Block b, double t0, T h);
  void kick_drift_step(Block b, double t0, T h);
  // A stage's state, the callbacks at time t, and the stage's rates.
  void evaluate(const kernels::RigidBlockJob<T>& job, Block b, double t);
  // The stage's rates from its state: every term's forces and torques at time t.
  void rates(const kernels::RigidBlockJob<T>& job, Block b, double t);
  void add_coupled(const kernels::RigidBlockJob<T>& job, Block b, double t);
  static RigidStage<T> stage_of(const kernels::RigidBlockJob<T>& job);
  void springs_pass(const kernels::RigidBlockJob<T>& job, const Workers& workers);
  void run_phases(const Call& call, const Workers& workers, double t0, const StopRequest* stop);
  bool keeps_state(const Workers& workers, const StopRequest* stop) const;
  double block_error(const Call& call, Block b, double rtol, double atol) const;
  const T* rate(int component, int stage) const;  // the rate of state component 0..12 at a stage
  void combine(T* const out[3], const T* const rate[3], T step, Block b) const;
  RigidBlock<T> view(const kernels::RigidBlockJob<T>& job, Block b, double t) const;

  const ForceModel<T>& forces_;
  const Method& method_;
  const kernels::KernelTable<T>& table_;
  const LoweredForces<T>& lowered_;
  RigidCoupling<T> coupling_;
  std::size_t capacity_ = 0;
  std::size_t padded_ = 0;  // the call's set, padded
  // Stage state (velocities per stage: they are the position rates), callback outputs, the
  // rates of each stage, and the state kept while user code may throw.
  std::array<AlignedArray<T>, 3> xs_, ls_, omega_, force_, torque_;
  std::array<AlignedArray<T>, 4> qs_;
  std::array<std::array<AlignedArray<T>, 3>, kMaxStages> vs_, kv_, kl_;
  std::array<std::array<AlignedArray<T>, 4>, kMaxStages> kq_;
  std::array<AlignedArray<T>, 13> saved_;
  AlignedArray<T> mass_;  // with callbacks or coupled terms: their views' masses (prepare)
  std::vector<double> block_error_;  // an attempt's sum of squared weighted errors per block
  // The call's jobs (prepare): per stage, the finish; per kick-drift operation, its step
  // (w h) and its turn.
  std::array<kernels::RigidBlockJob<T>, kMaxStages> stage_jobs_{}, turn_jobs_{};
  kernels::RigidBlockJob<T> finish_job_{};
  std::array<T, kMaxStages> op_steps_{};
};

extern template class RigidBlockPath<float>;
extern template class RigidBlockPath<double>;

}  // namespace kinema
