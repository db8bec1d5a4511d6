#include "step/fixed_steps.hpp"

#include "step/step_checks.hpp"

#include "kinema/dense_output.hpp"

#include <cmath>
#include <limits>
#include <string>
#include <type_traits>

namespace kinema {

template <class T>
std::size_t FixedSteps<T>::checkpoint_bytes() const {
  std::size_t previous = 0;
  for (const auto& a : previous_) previous += a.size() * sizeof(T);
  return checkpoint_.bytes() + buffer_.bytes() + call_start_.bytes() + previous + events_.bytes();
}

template <class T>
template <class Set>
void FixedSteps<T>::advance(const Workers& w, Set& b, T h, std::uint64_t steps, const StopRequest* stop) {
  check_step_count(h, steps);
  struct CallStop {  // the call's own: no later call sees it
    const StopRequest*& slot;
    CallStop(const StopRequest*& s, const StopRequest* stop) : slot(s) { slot = stop; }
    ~CallStop() { slot = nullptr; }
  } call_stop(stop_, stop);
  if (!events_.active()) return advance_checked(w, b, h, steps);
  check_events(b);
  events_.clear();
  constexpr bool rigid = std::is_same_v<Set, RigidBodySet<T>>;
  std::size_t capacity = 0;
  if constexpr (rigid) capacity = b.centers().capacity();
  else capacity = b.capacity();
  for (int a = 0; a < (!rigid ? 6 : events_.stops() ? 13 : 0); ++a) {
    if (previous_[a].size() != capacity) previous_[a] = AlignedArray<T>(capacity);
  }
  const OrderedHits<T> ordered{events_};
  const auto watched = [&] { return events_.stops() ? advance_to_stop(w, b, h, steps) : advance_checked(w, b, h, steps); };
  if (!events_.calls_user()) return watched();
  // A user's event function may throw with blocks at different steps: the set goes back to
  // where the call started (the guard's own NonFiniteError leaves it where it says).
  const StateArrays<T> state = state_arrays(b);
  call_start_.reserve(state);
  for_each_block(w, b.padded_size(), [&](Block block) { call_start_.save(state, block); });
  const Clock<T> clock = core_.clock;
  try {
    watched();
  } catch (const NonFiniteError&) {
    throw;
  } catch (...) {
    call_start_.restore(w, state);
    core_.clock = clock;
    events_.clear();
    throw;
  }
}

template <class T>
template <class Set>
void FixedSteps<T>::check_events(const Set& b) const {
  if (core_.paths.implicit) {
    throw Error("events are not watched under an implicit method (" + std::string(core_.method.name) +
                "): use an explicit one, or a stepper without events");
  }
  if constexpr (std::is_same_v<Set, RigidBodySet<T>>) {
    if (!centres_move_alone(core_.forces())) {
      throw Error("events on rigid bodies are watched with built-in local terms only (any method): this model has "
                  "rigid callbacks, point springs, body springs or coupled terms");
    }
  } else if (core_.paths.block || (core_.paths.fused_for(reads_per_body(b)) == nullptr && !core_.forces().fusable())) {
    throw Error("events are watched with built-in local terms only (any method): this model takes the " +
                std::string(core_.paths.block ? "block" : "staged") + " path for its callbacks or coupled terms");
  }
}

// The clock counts the steps of one size since its origin: a call that would take it past
// 2^64 is refused before anything moves (it would wrap, and time() jump back).
template <class T>
void FixedSteps<T>::check_step_count(T h, std::uint64_t steps) const {
  const std::uint64_t counted = h == core_.clock.h ? core_.clock.steps : 0;  // a new size starts a new count
  if (steps <= std::numeric_limits<std::uint64_t>::max() - counted) return;
  throw Error("advance: " + std::to_string(steps) + " steps after the clock's " + std::to_string(counted) +
              " of this size pass 2^64 (set_time or set_clock moves its origin)");
}

template <class T>
template <class Set>
void FixedSteps<T>::advance_to_stop(const Workers& w, Set& b, T h, std::uint64_t steps) {
  for (std::uint64_t k = 0; k < steps; ++k) {
    const double t0 = core_.clock.time();
    const std::size_t hits = events_.hits().size();
    try {
      advance_checked(w, b, h, 1);
    } catch (const NonFiniteError& e) {
      throw NonFiniteError(k + 1, e.time, e.body, e.field);
    }
    const auto stop = events_.first_stop();
    if (!stop) continue;
    steps_to_stop_ = k + 1;
    if (stop->theta == 1) return;
    try {
      settle(w, b, *stop, t0, h);
    } catch (...) {  // a host's enqueue: the step taken back, its hits and its stop too
      const StateArrays<T> state = state_arrays(b);
      for (int a = 0; a < state.count; ++a) std::copy(previous_[a].data(), previous_[a].data() + b.padded_size(), state.data[a]);
      --core_.clock.steps;
      events_.rollback(hits);
      throw;
    }
    core_.clock.set(stop->time);
    return;
  }
}

template <class T>
void FixedSteps<T>::settle(const Workers& w, ParticleSet<T>& b, const typename EventWatch<T>::Stop& stop, double,
                           T h) {
  const T* const before[6] = {previous_[0].data(), previous_[1].data(), previous_[2].data(),
                              previous_[3].data(), previous_[4].data(), previous_[5].data()};
  events_.settle(w, b, event_call(b), before, stop, double(h));
}

template <class T>
void FixedSteps<T>::settle(const Workers& w, RigidBodySet<T>& b, const typename EventWatch<T>::Stop& stop, double t0,
                           T h) {
  const T* before[13];
  for (int a = 0; a < 13; ++a) before[a] = previous_[a].data();
  events_.settle(w, b, core_.rigid_probe(), core_.options.renormalize_quaternions, before, stop, t0, double(h));
}

template <class T>
template <class Set>
std::optional<EventCall<T>> FixedSteps<T>::watch_adaptive(Set& b) {
  if (!events_.active()) return std::nullopt;
  check_events(b);
  events_.clear();
  return event_call(b);
}

template <class T>
EventCall<T> FixedSteps<T>::event_call(ParticleSet<T>& b) const {
  return {core_.table, core_.lowered().particle, b.inv_mass(), per_body(b), b.size(),
          has_dopri5_interpolant(core_.method)};
}

// A rigid body's centre moves as a particle under the rigid terms (check_events), located on
// the Hermite for every method, as RigidDenseOutput and a stop's settle have it.
template <class T>
EventCall<T> FixedSteps<T>::event_call(RigidBodySet<T>& b) const {
  return {core_.table, core_.lowered().rigid, b.centers().inv_mass(), per_body(b.centers()), b.size(), false};
}

template <class T>
template <class Set>
void FixedSteps<T>::advance_checked(const Workers& w, Set& b, T h, std::uint64_t steps) {
  if (core_.options.guard == FiniteGuard::off) return run(w, b, h, steps, nullptr);
  if constexpr (std::is_same_v<Set, ParticleSet<T>>) {
    if (buffers(b)) return advance_buffered(w, b, h, steps);
  }
  const StateArrays<T> state = state_arrays(b);
  checkpoint_.reserve(state);
  const Clock<T> start = core_.clock;  // whole: a new step size moves its origin (Clock::use)
  const std::size_t hits = events_.hits().size();
  std::optional<NonFinite> bad;
  try {
    bad = guarded_run(w, b, h, steps, state);
  } catch (...) {  // a stop, user code, a host's enqueue: the steps before it were not checked
    checkpoint_.restore(w, state);
    core_.clock = start;
    events_.rollback(hits);
    throw;
  }
  if (!bad) return;
  // Back to the start, then step by step to the step that made the value.
  checkpoint_.restore(w, state);
  core_.clock.steps -= steps;
  events_.rollback(hits);
  stop_ = nullptr;  // the steps were taken once: the search finishes
  std::size_t kept = hits;
  for (std::uint64_t k = 1; k <= steps; ++k) {
    if (const auto found = guarded_run(w, b, h, 1, state)) {
      checkpoint_.restore(w, state);
      --core_.clock.steps;
      events_.rollback(kept);  // the hits of the steps before it stay
      throw NonFiniteError(k, core_.clock.time(), found->body, found->field);
    }
    kept = events_.hits().size();
  }
}

template <class T>
bool FixedSteps<T>::buffers(const ParticleSet<T>& b) const {
  return !events_.active() && !core_.paths.block && core_.paths.fused_for(reads_per_body(b)) != nullptr;
}

// A call whose steps leave a value that is not finite leaves the set as it was; then one
// step at a time to the step that made it.
template <class T>
void FixedSteps<T>::advance_buffered(const Workers& w, ParticleSet<T>& b, T h, std::uint64_t steps) {
  buffer_.reserve(b);
  if (!buffered_run(w, b, h, steps)) return;
  for (std::uint64_t k = 1; k <= steps; ++k) {
    if (const auto found = buffered_run(w, b, h, 1)) {
      throw NonFiniteError(k, core_.clock.time(), found->body, found->field);
    }
  }
}

// Each block's first step reads the set and writes the buffer, its later steps run in the
// buffer (the same operations as in place, so the same bits), then it is scanned while in
// cache; a host's enqueue that throws leaves the set untouched.
template <class T>
std::optional<NonFinite> FixedSteps<T>::buffered_run(const Workers& w, ParticleSet<T>& b, T h,
                                                     std::uint64_t steps) {
  core_.reach(b);
  const LoweredForces<T>& lowered = core_.lowered();
  const StepContext<T> c = core_.start(b, h, lowered.particle, w);
  if (steps == 0) return std::nullopt;  // the buffer holds nothing of this call: no trade
  const kernels::FusedFn<T> fused_fn = core_.paths.fused_for(reads_per_body(b));
  const StateArrays<T> into = buffer_.arrays(b);
  kernels::BodyArrays<T> body = arrays(b);
  for (int d = 0; d < 3; ++d) body.x[d] = into.data[d], body.v[d] = into.data[3 + d];
  const kernels::FusedJob<T> in_buffer{body, lowered.particle, c.h};
  const T* const set_state[6] = {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()};
  kernels::FusedJob<T> from_set = in_buffer;
  from_set.source = set_state;
  FiniteScan<T> scan(into);
  const bool clamps = core_.options.guard == FiniteGuard::clamp;
  // In slices whose state stays in L1 from the kernel's stores to the scan's loads: bodies
  // are independent on this path, so a slice may take all the steps at once.
  constexpr std::size_t kSlice = 1024 / sizeof(T) * 2;
  for_each_block(w, b.padded_size(), [&](Block block) {
    for (std::size_t at = block.begin; at < block.end; at += kSlice) {
      const Block slice{at, std::min(at + kSlice, block.end)};
      for (std::uint64_t k = 0; k < steps; ++k) {
        fused_fn(k == 0 ? from_set : in_buffer, slice.begin, slice.end);
        if (clamps) clamp_speeds(body.v, b.inv_mass(), b.size(), slice, core_.options.max_speed);
      }
      scan.scan(slice);
    }
  });
  if (auto bad = scan.found()) return bad;
  buffer_.swap_into(b);
  core_.clock.steps += steps;
  return std::nullopt;
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
  if (core_.paths.implicit) {
    throw Error("implicit methods (" + std::string(core_.method.name) +
                ") step particle sets only: step rigid bodies with an explicit method");
  }
  const kernels::RigidFn<T> rigid_fn = core_.paths.rigid;
  const LoweredForces<T>& lowered = core_.lowered();
  core_.begin(h, lowered.rigid, b.parameters());
  if (rigid_fn == nullptr) {
    RigidBlockPath<T>& path = *core_.paths.rigid_block;
    if (path.coupled()) core_.reach(b.centers());
    path.reserve(b.padded_size());
    RigidBlocks blocks{path, {b, h, core_.options.renormalize_quaternions}};
    path.prepare(blocks.call);
    if (events_.active()) {
      return run_rigid_watched(w, b, h, steps, guard, kSliceBodies,
                               [&](Block s, double t0) { path.step_block(blocks.call, s, t0); });
    }
    if (!path.coupled()) return run_blocks(w, b, blocks, steps, guard);
    return run_steps(w, b, steps, guard, [&](double t0) { path.step_all(blocks.call, w, t0, stop_); });
  }
  const kernels::RigidJob<T> job{center_arrays(b), {b.q(0), b.q(1), b.q(2), b.q(3)},
                                 {b.l(0), b.l(1), b.l(2)},
                                 {b.inv_inertia(0), b.inv_inertia(1), b.inv_inertia(2)},
                                 lowered.rigid, lowered.rotation, h,
                                 core_.options.renormalize_quaternions,
                                 {b.applied_torque_data(0), b.applied_torque_data(1), b.applied_torque_data(2)},
                                 b.parameters().data(BodyParameter::angular_damping)};
  if (events_.active()) {
    return run_rigid_watched(w, b, h, steps, guard, kEventSliceBodies<T>,
                             [&](Block s, double) { rigid_fn(job, s.begin, s.end); });
  }
  for_each_block(w, b.padded_size(), [&](Block block) {
    run_block(b, block, steps, guard, [&](Block k) { rigid_fn(job, k.begin, k.end); });
  });
  core_.clock.steps += steps;
}

template <class T>
void FixedSteps<T>::run(const Workers& w, ParticleSet<T>& b, T h, std::uint64_t steps, Guard* guard) {
  core_.reach(b);
  const LoweredForces<T>& lowered = core_.lowered();
  StepContext<T> c = core_.start(b, h, lowered.particle, w);
  c.stop = stop_;
  const kernels::FusedFn<T> fused_fn = core_.paths.fused_for(reads_per_body(b));
  if (core_.paths.implicit) {
    ImplicitPath<T>& path = *core_.paths.implicit;
    return run_steps(w, b, steps, guard, [&](double t0) {
      c.t0 = t0;
      path.step(c);
    });
  }
  if (core_.paths.block) {
    BlockPath<T>& path = *core_.paths.block;
    path.reserve(b.padded_size());
    path.prepare(c);
    BlockPathBlocks blocks{path};
    return run_blocks(w, b, blocks, steps, guard);
  }
  if (fused_fn == nullptr) return run_staged(c, steps, guard);
  if (events_.active()) return run_watched(w, b, fused_fn, {arrays(b), lowered.particle, c.h}, steps, guard);
  // Local, time-independent forces: each block can take all its steps while it sits in
  // cache. Every body sees the same operations as step by step, so the bits agree.
  const kernels::FusedJob<T> job{arrays(b), lowered.particle, c.h};
  for_each_block(w, b.padded_size(), [&](Block block) {
    run_block(b, block, steps, guard, [&](Block k) { fused_fn(job, k.begin, k.end); });
  });
  core_.clock.steps += steps;
}

// The kernel steps each slice in place and writes the state each body started from as it
// goes (stores of values in registers, no extra loads): to scratch in L1, or to previous_
// when an event stops (a settle reads where every body started). The test then reads both
// ends of the step while the slice is in cache. Where every event is a built-in one and
// nothing changes the state after the kernel, the kernel runs their sign test itself and
// writes the start only of the batches where a body may have crossed, packed from its block's
// place in previous_ (lines that stay in cache): a slice is then a whole block, as without
// events.
template <class T>
void FixedSteps<T>::run_watched(const Workers& w, ParticleSet<T>& b, kernels::FusedFn<T> fused_fn,
                                const kernels::FusedJob<T>& job, std::uint64_t steps, Guard* guard) {
  const bool clamps = guard && guard->clamp;
  const Watched c{b, fused_fn, job, event_call(b), core_.clock, steps, clamps,
                  events_.stops() || clamps ? std::nullopt : events_.probe()};
  const std::size_t batches = b.padded_size() / c.call.table->width;
  if (c.probe && listed_.size() < batches) listed_.resize(batches);
  for_each_block(w, b.padded_size(), [&](Block block) {
    if (guard) guard->checkpoint.save(guard->state, block);
    if (c.probe) {
      watch_probed(c, block);
    } else {
      watch_slices(c, block);
    }
    if (guard) guard->scan.scan(block);
  });
  core_.clock.steps += steps;
}

// The fused job for the `count` bodies from s, writing their start to `before`: every array
// from the slice's first body.
template <class T>
kernels::FusedJob<T> FixedSteps<T>::slice_job(const Watched& c, std::size_t s, T* const* before) {
  kernels::FusedJob<T> job = c.job;
  ParticleSet<T>& b = c.bodies;
  T* const state[6] = {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()};
  for (int d = 0; d < 3; ++d) job.bodies.x[d] = state[d] + s, job.bodies.v[d] = state[3 + d] + s;
  job.bodies.inv_mass = c.job.bodies.inv_mass + s;
  job.bodies.per_body = c.job.bodies.per_body.from(s);
  job.before = before;
  return job;
}

template <class T>
SliceEnds<T> FixedSteps<T>::slice_ends(const Watched& c, std::size_t s, std::size_t count, T* const* before) {
  ParticleSet<T>& b = c.bodies;
  SliceEnds<T> ends{{before[0], before[1], before[2], before[3], before[4], before[5]}, {}, s, count};
  T* const state[6] = {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()};
  for (int a = 0; a < 6; ++a) ends.after[a] = state[a] + s;
  return ends;
}

template <class T>
double FixedSteps<T>::step_start(const Watched& c, std::uint64_t k) {
  Clock<T> now = c.start;
  now.steps += k;
  return now.time();
}

// Slices of a block in L1 (kept, or previous_ under a stop event), each tested after each step.
template <class T>
void FixedSteps<T>::watch_slices(const Watched& c, Block block) {
  alignas(64) T kept[6][kEventSliceBodies<T>];
  for (std::size_t s = block.begin; s < block.end; s += kEventSliceBodies<T>) {
    const std::size_t count = std::min(kEventSliceBodies<T>, block.end - s);
    T* before[6];
    for (int a = 0; a < 6; ++a) before[a] = events_.stops() ? previous_[a].data() + s : kept[a];
    const kernels::FusedJob<T> job = slice_job(c, s, before);
    const SliceEnds<T> ends = slice_ends(c, s, count, before);
    for (std::uint64_t k = 0; k < c.steps; ++k) {
      c.fused_fn(job, 0, count);
      if (c.clamps) clamp(c.bodies, {s, s + count});
      events_.scan(c.call, ends, step_start(c, k), double(c.job.h));
    }
  }
}

// The whole block under the kernel's probe, the listed batches' starts packed from the
// block's place in previous_ and their list in listed_ (no scratch on the stack: this runs
// once a block, where a frame's first touch is a miss).
template <class T>
void FixedSteps<T>::watch_probed(const Watched& c, Block block) {
  T* before[6];
  for (int a = 0; a < 6; ++a) before[a] = previous_[a].data() + block.begin;
  kernels::EventProbe<T> probe = *c.probe;
  probe.batches = listed_.data() + block.begin / c.call.table->width;
  kernels::FusedJob<T> job = slice_job(c, block.begin, before);
  job.probe = &probe;
  SliceEnds<T> ends = slice_ends(c, block.begin, block.end - block.begin, before);
  ends.batches = probe.batches;
  for (std::uint64_t k = 0; k < c.steps; ++k) {
    probe.found = 0;
    c.fused_fn(job, 0, block.end - block.begin);
    ends.batch_count = probe.found;
    events_.scan(c.call, ends, step_start(c, k), double(c.job.h));
  }
}

namespace {

template <class T>
void prefetch_slice(const StateArrays<T>& state, std::size_t begin, std::size_t end) {
  constexpr std::size_t kLine = 64 / sizeof(T);
  for (int a = 0; a < state.count; ++a) {
    for (std::size_t i = begin; i < end; i += kLine) __builtin_prefetch(state.data[a] + i);
  }
}

}  // namespace

template <class T>
template <class Step>
void FixedSteps<T>::run_rigid_watched(const Workers& w, RigidBodySet<T>& b, T h, std::uint64_t steps, Guard* guard,
                                      std::size_t slice_bodies, Step&& step) {
  const EventCall<T> call = event_call(b);
  const Clock<T> start = core_.clock;
  const StateArrays<T> state = state_arrays(b);
  const bool stops = events_.stops();
  const int kept = stops ? state.count : 6;
  for_each_block(w, b.padded_size(), [&](Block block) {
    if (guard) guard->checkpoint.save(guard->state, block);
    alignas(64) T slice_start[6][kEventSliceBodies<T>];  // without a stop, the start stays in cache
    for (std::size_t s = block.begin; s < block.end; s += slice_bodies) {
      const Block slice{s, std::min(s + slice_bodies, block.end)};
      T* before[StateArrays<T>::kMax];
      for (int a = 0; a < kept; ++a) before[a] = stops ? previous_[a].data() + s : slice_start[a];
      SliceEnds<T> ends{{}, {}, s, slice.end - s};
      for (int a = 0; a < 6; ++a) ends.before[a] = before[a], ends.after[a] = state.data[a] + s;
      for (std::uint64_t k = 0; k < steps; ++k) {
        for (int a = 0; a < kept; ++a) std::copy(state.data[a] + s, state.data[a] + slice.end, before[a]);
        // The next slice's state on its way while this one steps: its copy then reads the cache.
        if (k == 0) prefetch_slice(state, slice.end, std::min(slice.end + slice_bodies, block.end));
        Clock<T> now = start;
        now.steps += k;
        step(slice, now.time());
        if (guard && guard->clamp) clamp(b, slice);
        events_.scan(call, ends, now.time(), double(h));
      }
    }
    if (guard) guard->scan.scan(block);
  });
  core_.clock.steps += steps;
}

template <class T>
void FixedSteps<T>::run_staged(StepContext<T>& c, std::uint64_t steps, Guard* guard) {
  StagedPath<T>& staged = *core_.paths.staged;
  staged.reserve(c.bodies.padded_size());
  if (events_.active()) return run_staged_watched(c, steps, guard);
  if (!staged.blocks_alone()) {
    return run_steps(c.workers, c.bodies, steps, guard, [&](double t0) {
      c.t0 = t0;
      staged.step(c);
    });
  }
  staged.prepare(c);
  ParticleBlocks blocks{staged, c};
  run_blocks(c.workers, c.bodies, blocks, steps, guard);
}

// Events on the staged path (its methods with local terms only: check_events): each step
// keeps where the set started (previous_), then the sign test and the root finder read both
// ends slice by slice, as the fused path's scan does.
template <class T>
void FixedSteps<T>::run_staged_watched(StepContext<T>& c, std::uint64_t steps, Guard* guard) {
  StagedPath<T>& staged = *core_.paths.staged;
  ParticleSet<T>& b = c.bodies;
  const EventCall<T> call = event_call(b);
  const bool clamps = guard && guard->clamp;
  T* const state[6] = {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()};
  const T* const before[6] = {previous_[0].data(), previous_[1].data(), previous_[2].data(),
                              previous_[3].data(), previous_[4].data(), previous_[5].data()};
  run_steps(c.workers, b, steps, guard, [&](double t0) {
    for_each_block(c.workers, b.padded_size(), [&](Block block) {
      for (int a = 0; a < 6; ++a) std::copy(state[a] + block.begin, state[a] + block.end, previous_[a].data() + block.begin);
    });
    c.t0 = t0;
    staged.step(c);
    const std::size_t hits = events_.hits().size();
    try {
      if (clamps) for_each_block(c.workers, b.padded_size(), [&](Block block) { clamp(b, block); });
      events_.scan_blocks(c.workers, call, before, state, b.padded_size(), t0, double(c.h));
    } catch (...) {  // a host's enqueue, a user's event function: the step taken back, its hits too
      for (int a = 0; a < 6; ++a) std::copy(before[a], before[a] + b.padded_size(), state[a]);
      events_.rollback(hits);
      throw;
    }
  });
}

// The block path: each slice of a block takes every step of the call while its stage state is
// in L1, as the fused path keeps a block in cache; step k's callbacks see the clock's time k
// steps on. Where user code may throw,
// each block keeps its state as it starts. After a throw, blocks have run ahead of one
// another: every block started is put back and the steps before the first one that threw
// are taken again (callbacks are pure functions of their block, so they give the same
// bits), leaving the set as before that step. A throw while retaking them is the one that
// propagates.
template <class T>
template <class Set, class Path>
void FixedSteps<T>::run_blocks(const Workers& w, Set& set, Path& path, std::uint64_t steps, Guard* guard) {
  const std::size_t n = set.padded_size();
  const bool may_throw = path.may_throw();
  if (may_throw) {
    reserve_blocks(n);
    std::fill(completed_.begin(), completed_.end(), kNotRun);
  }
  const Clock<T> start = core_.clock;
  // User code's blocks poll the call's stop before they start: a stop then takes back what
  // ran ahead, as a throw does.
  const StopRequest* const stop = stop_;
  const bool polls = may_throw && stop != nullptr && *stop;
  try {
    for_each_block(w, n, [&](Block block) {
      // A slice takes every step of the call while its stage state stays in the L1 cache.
      // The slices before the one under way took every step: `done` is that slice's count.
      std::uint64_t done = 0;
      auto run = [&] {
        if (polls && (*stop)()) throw Stopped();
        if (guard) guard->checkpoint.save(guard->state, block);
        for (std::size_t s = block.begin; s < block.end; s += kSliceBodies) {
          const Block slice{s, std::min(s + kSliceBodies, block.end)};
          path.begin(slice);
          for (std::uint64_t k = 0; k < steps; ++k) {
            Clock<T> now = start;
            now.steps += k;
            done = k;
            path.step(slice, now.time());
            if (guard && guard->clamp) clamp(set, slice);
          }
        }
        done = steps;
        if (guard) guard->scan.scan(block);
      };
      if (!may_throw) return run();
      std::uint64_t& completed = completed_[block.begin / kBlockBodies];
      path.keep(block);
      try {
        run();
      } catch (...) {
        completed = done;
        throw;
      }
      completed = done;
    });
  } catch (...) {
    if (!may_throw) throw;  // a host job system's own failure: nothing of ours to put back
    std::uint64_t first = kNotRun;
    for (std::size_t i = 0; i < block_count(n); ++i) {
      if (completed_[i] == kNotRun) continue;
      first = std::min(first, completed_[i]);
      path.restore(block(i, n));
    }
    if (first != kNotRun && first > 0) {
      stop_ = nullptr;  // the steps were taken once: taking them again is not stopped
      run_blocks(w, set, path, first, guard);
    }
    throw;
  }
  core_.clock.steps += steps;
}

// One pass per step (and per stage where coupled terms need every body's stage state): the
// guard's save, clamp and scan are passes of their own.
template <class T>
template <class Set, class Step>
void FixedSteps<T>::run_steps(const Workers& w, Set& set, std::uint64_t steps, Guard* guard, Step&& step) {
  const std::size_t n = set.padded_size();
  const std::uint64_t start = core_.clock.steps;
  // A host's enqueue that throws in one of the guard's own passes leaves steps unchecked
  // (or unclamped): the set and the clock go back to where the call started.
  const auto guard_pass = [&](auto&& pass) {
    try {
      for_each_block(w, n, pass);
    } catch (...) {
      guard->checkpoint.restore(w, guard->state);
      core_.clock.steps = start;
      throw;
    }
  };
  if (guard) for_each_block(w, n, [&](Block b) { guard->checkpoint.save(guard->state, b); });
  for (std::uint64_t k = 0; k < steps; ++k) {
    step(core_.clock.time());
    ++core_.clock.steps;
    if (guard && guard->clamp) guard_pass([&](Block b) { clamp(set, b); });
  }
  if (guard) guard_pass([&](Block b) { guard->scan.scan(b); });
}

template class FixedSteps<float>;
template class FixedSteps<double>;
template std::optional<EventCall<float>> FixedSteps<float>::watch_adaptive(ParticleSet<float>&);
template std::optional<EventCall<float>> FixedSteps<float>::watch_adaptive(RigidBodySet<float>&);
template std::optional<EventCall<double>> FixedSteps<double>::watch_adaptive(ParticleSet<double>&);
template std::optional<EventCall<double>> FixedSteps<double>::watch_adaptive(RigidBodySet<double>&);
template void FixedSteps<float>::advance(const Workers&, ParticleSet<float>&, float, std::uint64_t, const StopRequest*);
template void FixedSteps<float>::advance(const Workers&, RigidBodySet<float>&, float, std::uint64_t, const StopRequest*);
template void FixedSteps<double>::advance(const Workers&, ParticleSet<double>&, double, std::uint64_t,
                                          const StopRequest*);
template void FixedSteps<double>::advance(const Workers&, RigidBodySet<double>&, double, std::uint64_t,
                                          const StopRequest*);

}  // namespace kinema
