#pragma once
// The fixed-step driver: `steps` steps of one size on the fused or the staged path, with the
// finiteness guard's work (StepperOptions::guard) around them.

#include <cstdint>
#include <algorithm>
#include <array>
#include <optional>
#include <vector>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "parallel/blocks.hpp"
#include "step/event_watch.hpp"
#include "step/finite_guard.hpp"
#include "step/stepper_core.hpp"

namespace kinema {

template <class T>
class FixedSteps {
 public:
  explicit FixedSteps(StepperCore<T>& core) : core_(core) {}

  // Advances the set on `workers`. Under a guard, a step that leaves a value that is not
  // finite puts the bodies and the clock back to the step before it and throws
  // NonFiniteError.
  // `stop` (may be null) is polled inside the steps of coupled terms (StepContext::stop):
  // once it says stop, kinema::Stopped is thrown, the set and the clock at the last step
  // completed. Under a guard, whatever a call throws (a stop, user code, a host's enqueue)
  // leaves them where the call started: its steps were not checked (where the guard checks
  // one step at a time, its NaN search and stop events, where the last checked step left them).
  // (Instantiated for ParticleSet<T> and RigidBodySet<T>.)
  template <class Set>
  void advance(const Workers& workers, Set& bodies, T h, std::uint64_t steps, const StopRequest* stop = nullptr);

  // kinema::Error when `steps` of size h would take the clock's count of steps past 2^64.
  void check_step_count(T h, std::uint64_t steps) const;

  std::size_t checkpoint_bytes() const;
  // The events watched by the steps (kinema/events.hpp), and the hits of the last call.
  EventWatch<T>& events() { return events_; }
  const EventWatch<T>& events() const { return events_; }
  // The steps the last call took when a stop event ended it (its last one cut at the event).
  std::uint64_t steps_to_stop() const { return steps_to_stop_; }
  // Events under advance_to: refuses a model they cannot be watched on, clears the last
  // call's hits and gives what the adaptive driver's scans read; nothing without events.
  // (Instantiated for ParticleSet<T> and RigidBodySet<T>.)
  template <class Set>
  std::optional<EventCall<T>> watch_adaptive(Set& b);
  // What the block paths keep per block for `padded` bodies (allocates only to grow).
  void reserve_blocks(std::size_t padded) { completed_.resize(std::max(completed_.size(), block_count(padded))); }

 private:
  // What the guard does inside a call: save each block before its steps, clamp after every
  // step, scan each block after its last (on the fused path while the block is in cache).
  struct Guard {
    const StateArrays<T>& state;
    Checkpoint<T>& checkpoint;
    FiniteScan<T> scan;
    bool clamp;
  };

  // advance without events' stop: the guard's work around the steps.
  template <class Set>
  void advance_checked(const Workers& w, Set& b, T h, std::uint64_t steps);
  // Stop events: one step at a time, each watched; the first stop settles the set there.
  template <class Set>
  void advance_to_stop(const Workers& w, Set& b, T h, std::uint64_t steps);
  // Every body on the dense output at the stop, `previous_` holding the step's start at t0
  // (EventWatch::settle).
  void settle(const Workers& w, RigidBodySet<T>& b, const typename EventWatch<T>::Stop& stop, double t0, T h);
  void settle(const Workers& w, ParticleSet<T>& b, const typename EventWatch<T>::Stop& stop, double t0, T h);
  template <class Set>
  void check_events(const Set& b) const;
  // The fused particle path with events: each slice of a block takes its steps in L1 and is
  // tested after each, both ends of the step at hand.
  void run_watched(const Workers& w, ParticleSet<T>& b, kernels::FusedFn<T> fused_fn,
                   const kernels::FusedJob<T>& job, std::uint64_t steps, Guard* guard);
  // What run_watched's blocks share.
  struct Watched {
    ParticleSet<T>& bodies;
    kernels::FusedFn<T> fused_fn;
    const kernels::FusedJob<T>& job;
    EventCall<T> call;
    Clock<T> start;
    std::uint64_t steps;
    bool clamps;
    std::optional<kernels::EventProbe<T>> probe;  // the kernel's own sign test, where it runs
  };
  [[gnu::noinline]] void watch_slices(const Watched& c, Block block);  // its scratch, its own frame
  void watch_probed(const Watched& c, Block block);
  static kernels::FusedJob<T> slice_job(const Watched& c, std::size_t s, T* const* before);
  static SliceEnds<T> slice_ends(const Watched& c, std::size_t s, std::size_t count, T* const* before);
  static double step_start(const Watched& c, std::uint64_t k);
  EventCall<T> event_call(ParticleSet<T>& b) const;
  EventCall<T> event_call(RigidBodySet<T>& b) const;
  // Rigid bodies with events: each slice of a block (`slice_bodies`, at most
  // kEventSliceBodies) takes every step in cache, its centres' start kept beside it before
  // each (under a stop event all 13 components, in previous_, which a settle reads), then
  // scanned. step(slice, t0) steps a slice.
  template <class Step>
  void run_rigid_watched(const Workers& w, RigidBodySet<T>& b, T h, std::uint64_t steps, Guard* guard,
                         std::size_t slice_bodies, Step&& step);
  template <class Set>
  std::optional<NonFinite> guarded_run(const Workers& w, Set& b, T h, std::uint64_t steps,
                                       const StateArrays<T>& state);
  // The fused particle path under a guard: steps into buffer_, which the set takes when
  // every value is finite (finite_guard.hpp): no copy to save, none to put back.
  bool buffers(const ParticleSet<T>& b) const;
  void advance_buffered(const Workers& w, ParticleSet<T>& b, T h, std::uint64_t steps);
  std::optional<NonFinite> buffered_run(const Workers& w, ParticleSet<T>& b, T h, std::uint64_t steps);
  template <class Set, class Step>
  void run_block(Set& b, Block block, std::uint64_t steps, Guard* guard, Step&& step);
  void run(const Workers& w, RigidBodySet<T>& b, T h, std::uint64_t steps, Guard* guard);
  void run(const Workers& w, ParticleSet<T>& b, T h, std::uint64_t steps, Guard* guard);
  void run_staged(StepContext<T>& c, std::uint64_t steps, Guard* guard);
  void run_staged_watched(StepContext<T>& c, std::uint64_t steps, Guard* guard);
  // Steps of a path whose phases are passes over every block: step(t0) takes one.
  template <class Set, class Step>
  void run_steps(const Workers& w, Set& set, std::uint64_t steps, Guard* guard, Step&& step);
  template <class Set, class Path>
  void run_blocks(const Workers& w, Set& set, Path& path, std::uint64_t steps, Guard* guard);

  // The block paths as run_blocks takes them: may_throw(), keep and restore a block, begin a
  // slice's steps of a call and step a slice.
  // A slice of a block takes every step of a call, every phase over the slice, whose stage
  // state stays in the L1 cache meanwhile (see kernels::kSliceBodies).
  static constexpr std::size_t kSliceBodies = kernels::kSliceBodies<T>;
  struct ParticleBlocks {
    StagedPath<T>& staged;
    const StepContext<T>& c;
    bool may_throw() const { return staged.may_throw(); }
    void keep(Block b) { staged.keep_block(c, b); }
    void restore(Block b) { staged.restore_block(c, b); }
    void begin(Block) {}
    void step(Block b, double t0) {
      StepContext<T> at = c;
      at.t0 = t0;
      staged.step_block(at, b);
    }
  };
  struct BlockPathBlocks {
    BlockPath<T>& path;
    bool may_throw() const { return path.may_throw(); }
    void keep(Block b) { path.keep_block(b); }
    void restore(Block b) { path.restore_block(b); }
    void begin(Block b) { path.begin_slice(b); }
    void step(Block b, double t0) { path.step_block(b, t0); }
  };
  struct RigidBlocks {
    RigidBlockPath<T>& path;
    typename RigidBlockPath<T>::Call call;
    bool may_throw() const { return path.may_throw(); }
    void keep(Block b) { path.keep_block(call, b); }
    void restore(Block b) { path.restore_block(call, b); }
    void begin(Block) {}
    void step(Block b, double t0) { path.step_block(call, b, t0); }
  };
  void clamp(ParticleSet<T>& b, Block block) const;
  void clamp(RigidBodySet<T>& b, Block block) const;

  StepperCore<T>& core_;
  const StopRequest* stop_ = nullptr;  // the call's, while it runs
  Checkpoint<T> checkpoint_;  // the state a guarded call starts from
  StateBuffer<T> buffer_;     // or, on the fused particle path, where it steps to
  EventWatch<T> events_;
  // Events: where each body's last step started (every body under a stop event, else the
  // batches the kernel's probe listed): px .. vz, and for rigid bodies (under a stop event
  // only) q and L too.
  std::array<AlignedArray<T>, 13> previous_;
  std::vector<std::uint32_t> listed_;  // the batches the probe listed, each block's from its first batch
  std::uint64_t steps_to_stop_ = 0;
  Checkpoint<T> call_start_;  // events with a user function: the state a call starts from
  // The block path, when user code may throw: per block, the steps it completed (kNotRun for
  // a block the call never started).
  static constexpr std::uint64_t kNotRun = ~std::uint64_t(0);
  std::vector<std::uint64_t> completed_;
};

extern template class FixedSteps<float>;
extern template class FixedSteps<double>;

}  // namespace kinema
