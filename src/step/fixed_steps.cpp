#include "step/fixed_steps.hpp"

#include "step/step_checks.hpp"

namespace kinema {

template <class T>
template <class Set>
void FixedSteps<T>::advance(const Workers& w, Set& b, T h, std::uint64_t steps) {
  if (core_.options.guard == FiniteGuard::off) return run(w, b, h, steps, nullptr);
  const StateArrays<T> state = state_arrays(b);
  checkpoint_.reserve(state);
  if (!guarded_run(w, b, h, steps, state)) return;
  // Back to the start, then step by step to the step that made the value.
  checkpoint_.restore(w, state);
  core_.clock.steps -= steps;
  for (std::uint64_t k = 1; k <= steps; ++k) {
    if (const auto bad = guarded_run(w, b, h, 1, state)) {
      checkpoint_.restore(w, state);
      --core_.clock.steps;
      throw NonFiniteError(k, core_.clock.time(), bad->body, bad->field);
    }
  }
}

template <class T>
template <class Set>
std::optional<NonFinite> FixedSteps<T>::guarded_run(const Workers& w, Set& b, T h, std::uint64_t steps,
                                                    const StateArrays<T>& state) {
  Guard guard{state, checkpoint_, FiniteScan<T>(state), core_.options.guard == FiniteGuard::clamp};
  run(w, b, h, steps, &guard);
  return guard.scan.found();
}

template <class T>
void FixedSteps<T>::clamp(ParticleSet<T>& b, Block block) const {
  clamp_speeds(b, block, core_.options.max_speed);
}

template <class T>
void FixedSteps<T>::clamp(RigidBodySet<T>& b, Block block) const {
  clamp_speeds(b, block, core_.options.max_speed, core_.options.max_angular_speed);
}

// A block's steps with the guard's work around them. Each body's steps are the same
// operations whether its block takes them in one go or one at a time.
template <class T>
template <class Set, class Step>
void FixedSteps<T>::run_block(Set& b, Block block, std::uint64_t steps, Guard* guard, Step&& step) {
  if (guard) guard->checkpoint.save(guard->state, block);
  for (std::uint64_t k = 0; k < steps; ++k) {
    step(block);
    if (guard && guard->clamp) clamp(b, block);
  }
  if (guard) guard->scan.scan(block);
}

template <class T>
void FixedSteps<T>::run(const Workers& w, RigidBodySet<T>& b, T h, std::uint64_t steps, Guard* guard) {
  const kernels::RigidFn<T> rigid_fn = core_.paths.rigid_for(b.has_applied_forces());
  if (rigid_fn == nullptr) {
    throw Error("rigid bodies need a built-in method and local force terms only (no "
                "callbacks, no coupled terms)");
  }
  const LoweredForces<T>& lowered = core_.lowered();
  core_.begin(h, lowered.rigid);
  const kernels::RigidJob<T> job{center_arrays(b), {b.q(0), b.q(1), b.q(2), b.q(3)},
                                 {b.l(0), b.l(1), b.l(2)},
                                 {b.inv_inertia(0), b.inv_inertia(1), b.inv_inertia(2)},
                                 lowered.rigid, lowered.rotation, h,
                                 core_.options.renormalize_quaternions,
                                 {b.applied_torque_data(0), b.applied_torque_data(1), b.applied_torque_data(2)}};
  for_each_block(w, b.padded_size(), [&](Block block) {
    run_block(b, block, steps, guard, [&](Block k) { rigid_fn(job, k.begin, k.end); });
  });
  core_.clock.steps += steps;
}

template <class T>
void FixedSteps<T>::run(const Workers& w, ParticleSet<T>& b, T h, std::uint64_t steps, Guard* guard) {
  const LoweredForces<T>& lowered = core_.lowered();
  check_reach(lowered.coupled, b);
  StepContext<T> c = core_.start(b, h, lowered.particle, w);
  const kernels::FusedFn<T> fused_fn = core_.paths.fused_for(b.has_applied_forces());
  if (fused_fn == nullptr) return run_staged(c, steps, guard);
  // Local, time-independent forces: each block can take all its steps while it sits in
  // cache. Every body sees the same operations as step by step, so the bits agree.
  const kernels::FusedJob<T> job{arrays(b), lowered.particle, c.h};
  for_each_block(w, b.padded_size(), [&](Block block) {
    run_block(b, block, steps, guard, [&](Block k) { fused_fn(job, k.begin, k.end); });
  });
  core_.clock.steps += steps;
}

// One pass per stage: the guard's save, clamp and scan are passes of their own.
template <class T>
void FixedSteps<T>::run_staged(StepContext<T>& c, std::uint64_t steps, Guard* guard) {
  StagedPath<T>& staged = *core_.paths.staged;
  staged.reserve(c.bodies.padded_size());
  const std::size_t n = c.bodies.padded_size();
  if (guard) for_each_block(c.workers, n, [&](Block b) { guard->checkpoint.save(guard->state, b); });
  for (std::uint64_t k = 0; k < steps; ++k) {
    c.t0 = core_.clock.time();
    staged.step(c);
    ++core_.clock.steps;
    if (guard && guard->clamp) for_each_block(c.workers, n, [&](Block b) { clamp(c.bodies, b); });
  }
  if (guard) for_each_block(c.workers, n, [&](Block b) { guard->scan.scan(b); });
}

template class FixedSteps<float>;
template class FixedSteps<double>;
template void FixedSteps<float>::advance(const Workers&, ParticleSet<float>&, float, std::uint64_t);
template void FixedSteps<float>::advance(const Workers&, RigidBodySet<float>&, float, std::uint64_t);
template void FixedSteps<double>::advance(const Workers&, ParticleSet<double>&, double, std::uint64_t);
template void FixedSteps<double>::advance(const Workers&, RigidBodySet<double>&, double, std::uint64_t);

}  // namespace kinema
