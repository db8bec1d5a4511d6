#pragma once
// The staged path: one pass per stage (or kick, drift) over every block, the stage state
// in memory. It takes what the fused kernels cannot: callbacks, coupled terms, user
// tableaus. Without coupled terms a block runs all phases of a step while in cache; a
// coupled term reads every body's stage state, so each phase is then a job of its own.

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"
#include "kinema/job_system.hpp"
#include "kinema/methods.hpp"
#include "parallel/blocks.hpp"
#include "step/step_context.hpp"

namespace kinema {

template <class T>
class StagedPath {
 public:
  // Keeps references: every argument must outlive the path.
  StagedPath(const ForceModel<T>& forces, const Method& method,
             const kernels::KernelTable<T>& table, const kernels::LocalForces<T>& local,
             const CoupledForces<T>& coupled);

  // Scratch for `padded` bodies (a padded count); allocates only when it grows.
  void reserve(std::size_t padded);
  std::size_t capacity() const { return capacity_; }
  std::size_t bytes() const;  // of the scratch arrays
  // One step, its blocks run where the context's workers say. When user
  // code (a callback or a CoupledTerm) throws, the bodies are put back as they were and the
  // exception is rethrown here, on the calling thread.
  void step(const StepContext<T>& context);

  // Error control, for a method with an embedded pair: one step that can be taken back.
  struct Attempt {
    double rtol = 0, atol = 0;
    // > 0: stage 0's accelerations are the ones kept (see keep_last_stage) times this, the
    // ratio of this step's acceleration scale to theirs; 0: they are evaluated.
    T reuse_scale = 0;
  };
  // Runs one step as step() does, keeping the state it started from, and returns the error
  // estimate's weighted RMS norm: sqrt(mean over every body's position and velocity
  // components of (e / (atol + rtol max(|y0|, |y1|)))^2), e the difference of the two
  // solutions. Blocks' sums are added in block order, so the norm does not depend on threads.
  double attempt(const StepContext<T>& context, const Attempt& a);
  // Puts back the state the last attempt started from, in the blocks it reached (an attempt
  // that threw may have reached none). Where the host's enqueue throws, on the calling thread,
  // and the exception goes on.
  void take_back(const StepContext<T>& context);
  // After a rejected attempt of size context.h (taken back): the body and component (0..5:
  // x, y, z, vx, vy, vz) whose weighted error was largest, weights from the state kept.
  struct WorstError {
    std::size_t body = 0;
    int component = 0;
    double weighted = 0;
  };
  WorstError worst_error(const StepContext<T>& context, double rtol, double atol) const;
  // After an accepted step of a method whose last stage is evaluated at the new state: that
  // stage's accelerations become the ones kept for the next attempt's stage 0.
  void keep_last_stage();
  // Evaluates stage 0 alone (the accelerations at the bodies' state, times the context's
  // acceleration scale) and keeps them as an attempt's reuse_scale expects.
  void evaluate_first_stage(const StepContext<T>& context);
  // Stage 0's accelerations (times the scale they were evaluated with), for the driver's
  // first step size.
  std::array<const T*, 3> first_stage() const { return accelerations(0); }
  // Where the last attempt started (px .. vz), for a method with an embedded pair.
  std::array<const T*, 6> attempt_start() const {
    return {saved_[0][0].data(), saved_[0][1].data(), saved_[0][2].data(),
            saved_[1][0].data(), saved_[1][1].data(), saved_[1][2].data()};
  }
  // Stage 0's accelerations to write into (a checkpoint's kept first stage), `padded` long.
  std::array<T*, 3> first_stage_for(std::size_t padded) {
    reserve(padded);
    return {stage_a_[0][0].data(), stage_a_[0][1].data(), stage_a_[0][2].data()};
  }

  // The block path (no coupled terms): a driver may run each slice of a block through all the
  // steps of a call while it is in cache, one step_block per step. A block's steps see nothing of
  // the others, so the bits are those of step().
  bool blocks_alone() const { return !coupled(); }
  bool may_throw() const { return !forces_.callbacks().empty() || !forces_.coupled_terms().empty(); }
  // Builds the phases' jobs for the call's bodies and step size: before any step_block.
  void prepare(const StepContext<T>& c);
  void step_block(const StepContext<T>& c, Block b) { run_block(c, b); }
  // Keeps the block's positions and velocities (save), or puts them back.
  void keep_block(const StepContext<T>& c, Block b) { copy_state(c, b, true); }
  void restore_block(const StepContext<T>& c, Block b) { copy_state(c, b, false); }

 private:
  enum class PhaseKind { stage, coupled, finish, kick, drift };
  struct Phase {
    PhaseKind kind;
    int index;  // stage or operation
  };
  static constexpr int kMaxPhases = 3 * kMaxStages + 1;

  void plan();
  void run_phases(const StepContext<T>& c);
  // Saves the block's positions and velocities to saved_, or puts them back.
  void copy_state(const StepContext<T>& c, Block b, bool save);
  // An attempt's save of a block, marked for take_back.
  void save_for_attempt(const StepContext<T>& c, Block b);
  bool coupled() const { return forces_.coupled(); }
  bool needs_force_scratch() const { return coupled() || !forces_.callbacks().empty(); }
  // Whether user code sees views (callbacks, coupled terms): only then are masses formed.
  bool user_views() const { return !forces_.callbacks().empty() || !forces_.coupled_terms().empty(); }

  bool own_state(int s) const;
  const T* state_x(const StepContext<T>& c, int s, int d) const;
  const T* state_v(const StepContext<T>& c, int s, int d) const;
  std::array<const T*, 3> velocities(const StepContext<T>& c, int s) const;
  std::array<const T*, 3> accelerations(int s) const;
  int accel_slot(const Phase& p) const;
  double phase_time(const StepContext<T>& c, const Phase& p) const;
  ParticleBlock<T> block_view(const StepContext<T>& c, int s, Block b, double t);

  void run_block(const StepContext<T>& c, Block b);
  void run(const StepContext<T>& c, const Phase& p, Block b);
  bool skipped(const Phase& p) const;
  void scale_first_stage(Block b);
  double block_error(const StepContext<T>& c, Block b) const;
  // The error's terms for one component: e_i = sum_s w[s] k[s][i] (k offset to body 0).
  void error_terms(const StepContext<T>& c, int field, int d, std::array<const T*, kMaxStages>& k,
                   std::array<double, kMaxStages>& w) const;
  void run_stage(const StepContext<T>& c, const Phase& p, Block b);
  void run_coupled(const StepContext<T>& c, const Phase& p, Block b);
  void add_gravity(const StepContext<T>& c, int s, Block b);
  void add_springs(const StepContext<T>& c, int s, Block b);
  void run_finish(const StepContext<T>& c, Block b);
  void run_kick_drift(const Phase& p, Block b);
  kernels::StageJob<T> stage_job(const StepContext<T>& c, int s);
  std::array<kernels::CombineJob<T>, 2> finish_jobs(const StepContext<T>& c);
  kernels::CombineJob<T> kick_drift_job(const StepContext<T>& c, int op) const;
  void add_forces(const StepContext<T>& c, int s, Block b);
  void set_steps(const StepContext<T>& c, const kernels::RowSum& row, kernels::Combination<T>& x,
                 kernels::Combination<T>& v) const;

  const ForceModel<T>& forces_;
  const Method& method_;
  const kernels::KernelTable<T>& table_;
  const kernels::LocalForces<T>& local_;
  const CoupledForces<T>& coupled_;
  std::array<Phase, kMaxPhases> phases_{};
  int phase_count_ = 0;
  std::size_t capacity_ = 0;
  // Stage positions and velocities (stage 0 is the bodies themselves), stage accelerations,
  // and the force accumulator of callback and coupled terms. Blocks write disjoint ranges.
  std::array<std::array<AlignedArray<T>, 3>, kMaxStages> stage_x_, stage_v_, stage_a_;
  std::array<AlignedArray<T>, 3> force_;
  AlignedArray<T> mass_;  // where user code sees views: their masses (fill_masses)
  std::array<std::array<AlignedArray<T>, 3>, 2> saved_;  // x and v before a step that may throw
  // The call's jobs (prepare): per stage slot, the finish (x, v), per kick-drift operation.
  std::array<kernels::StageJob<T>, kMaxStages> stage_jobs_{};
  std::array<kernels::CombineJob<T>, 2> finish_jobs_{};
  std::array<kernels::CombineJob<T>, kMaxStages> kick_drift_jobs_{};
  // The attempt in progress (error control), and each block's sum of squared weighted errors.
  const Attempt* attempt_ = nullptr;
  bool first_stage_only_ = false;
  std::vector<double> block_error_;
  std::vector<std::uint8_t> block_saved_;  // whether the attempt saved the block (bytes: blocks write their own)
  bool keeps_state() const { return may_throw() || method_.embedded_order > 0 || phases_change_bodies(); }
  // More than one pass of a step changes the bodies (kick-drift methods with coupled terms:
  // each kick and drift is a pass of its own); else only the last pass does.
  bool phases_change_bodies() const { return method_.kind == MethodKind::kick_drift && coupled(); }
  // Whether a step polls c.stop: only where a pass takes long (N-body gravity's n per body,
  // user code); a spring pass takes microseconds a block, not worth keeping the state for.
  bool polls(const StepContext<T>& c) const { return c.stop && *c.stop && (coupled_.nbody || may_throw()); }
  // An attempt saves each block as it starts on it, unless a block may throw (then every
  // block must be saved before any runs, to put them all back) or phases run as jobs of
  // their own.
  bool saves_in_block() const { return !may_throw() && !coupled(); }
};

extern template class StagedPath<float>;
extern template class StagedPath<double>;

}  // namespace kinema
