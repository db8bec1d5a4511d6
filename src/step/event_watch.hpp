#pragma once
// Events inside a step (kinema/events.hpp): the sign test over a slice of bodies at both ends
// of a step, the root finder on the dense output for the bodies that crossed, the hits of a
// call, and a set brought to a stop event's time.

#include <cstddef>
#include <cstdint>
#include <array>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/events.hpp"
#include "parallel/blocks.hpp"

namespace kinema {

struct StepEnds;  // kinema/dense_output.hpp

template <class T>
class RigidBlockPath;

// Bodies per slice of the sign test: a slice's state at the step's start (the kernel's
// stores) and end stay in L1 from the kernel's stores to the test's loads.
template <class T>
inline constexpr std::size_t kEventSliceBodies = 2048 / sizeof(T);

// What the events of a call read besides the bodies' states: the model's local terms, for
// the accelerations at a crossing body's two ends.
template <class T>
struct EventCall {
  const kernels::KernelTable<T>* table = nullptr;
  kernels::LocalForces<T> forces;
  const T* inv_mass = nullptr;
  kernels::PerBody<T> per_body{};
  std::size_t size = 0;  // real bodies
  bool dopri5 = false;    // the steps have dopri5's own interpolant (kinema/dense_output.hpp)
};

// One slice of bodies at both ends of a step, every array from the slice's first body.
template <class T>
struct SliceEnds {
  const T* before[6];  // px .. vz at the step's start
  const T* after[6];   // and at its end
  std::size_t first;   // the slice's first body
  std::size_t count;   // bodies, padding included (a multiple of the SIMD width)
  // The batches (offsets of their first bodies) the fused kernel's probe found a crossing
  // in; `before` holds those batches only, packed (the k-th at k * width). Null: every batch,
  // all of `before`.
  const std::uint32_t* batches = nullptr;
  std::size_t batch_count = 0;
};

template <class T>
class EventWatch {
 public:
  // Checks the events (kinema::Error naming the event and its field) and keeps them.
  void set(EventOptions<T> options);
  bool active() const { return !events_.empty(); }
  // Whether an event stops the call: then steps run one pass each over the whole set.
  bool stops() const { return stops_; }
  // Whether an event is a user's function (which may throw).
  bool calls_user() const { return calls_user_; }
  // The sign test a fused kernel can run as it steps, when every event is a built-in one.
  std::optional<kernels::EventProbe<T>> probe() const;

  // Forgets the hits (a call starts, or steps are taken again).
  void clear();
  // The slice's bodies that crossed over the step [t0, t0 + h]: located and recorded. May be
  // called for different slices concurrently.
  void scan(const EventCall<T>& call, const SliceEnds<T>& slice, double t0, double h);
  // Every slice of the set's `padded` bodies, `before` and `after` holding both ends of the
  // step in full, blocks spread over the workers.
  void scan_blocks(const Workers& workers, const EventCall<T>& call, const T* const before[6],
                   const T* const after[6], std::size_t padded, double t0, double h);
  // Bytes of the settles' scratch and of the hits' ordering.
  std::size_t bytes() const;
  // Forgets the hits recorded after the first `kept` (steps taken back).
  void rollback(std::size_t kept);
  // The earliest stop hit recorded, if any: its time and the fraction of its step.
  struct Stop {
    double time, theta;
    std::size_t body;
    int event;
  };
  std::optional<Stop> first_stop() const;
  std::optional<double> stop_time() const {
    const auto stop = first_stop();
    return stop ? std::optional<double>(stop->time) : std::nullopt;
  }
  // Orders the hits (time, body, event) and drops those after `until`.
  void finish(std::optional<double> until);
  const std::vector<EventHit<T>>& hits() const { return hits_; }

  // Puts every body of the set (at the step's end now, `before` its start) on the dense
  // output at theta of the step of size h: where a stop event ended the call.
  // The set is left at `stop`: a body whose crossing was reported at the stop's time (within
  // sqrt(epsilon of T) of the step), and whose state in T may lie a rounding short of it,
  // is not found crossing again at the next call's start (the stop's body, and any other
  // event or body crossing with it).
  void settle(const Workers& workers, ParticleSet<T>& bodies, const EventCall<T>& call,
              const T* const before[6], const Stop& stop, double h);
  // Every rigid body (at the step's end now, `before` its 13 components at its start t0) on
  // the Hermite of its components and their rates at both ends (`probe`'s), at the stop, the
  // orientation normalized; padding stays as the step left it.
  void settle(const Workers& workers, RigidBodySet<T>& bodies, RigidBlockPath<T>& probe, bool renormalize,
              const T* const before[13], const Stop& stop, double t0, double h);

 private:
  void scan_listed(const EventCall<T>& call, const SliceEnds<T>& slice, double t0, double h);
  [[gnu::noinline]] void scan_all(const EventCall<T>& call, const SliceEnds<T>& slice, double t0, double h);
  std::size_t candidates(int e, const EventCall<T>& call, const SliceEnds<T>& slice, std::size_t real, double t0,
                         double h, std::uint32_t* found) const;
  void locate(int e, const EventCall<T>& call, const SliceEnds<T>& slice, std::size_t local, double t0, double h);
  // settle's record of the stop and of the (body, event) hits at its time, with the position
  // each body was settled at (`state`: its position arrays, then its velocity arrays).
  void remember_settled(const Stop& stop, double h, const T* const* state);
  bool found_at_settle(std::size_t body, int e, double t0, double theta, const StepEnds& ends) const;

  std::vector<Event<T>> events_;
  std::vector<kernels::EventScanJob<T>> jobs_;  // the built-in events' sign tests
  double tolerance_ = 0;
  bool stops_ = false;
  bool calls_user_ = false;
  mutable std::mutex mutex_;  // hits_ and stop_
  std::vector<EventHit<T>> hits_;
  // finish's order: each hit's key and place, and the hits in order (kept for their capacity).
  struct HitKey {
    double time;
    std::size_t body;
    int event;
    std::size_t index;
  };
  std::vector<HitKey> order_, merged_;
  std::vector<std::size_t> buckets_;
  std::vector<EventHit<T>> sorted_;
  static void sort_keys(std::vector<HitKey>& keys, std::vector<HitKey>& scratch, std::vector<std::size_t>& ends);
  std::optional<Stop> stop_;
  std::optional<Stop> settled_;  // the stop the set was last left at
  // A hit reported at the stop's time: its body and event, and the body's position as
  // settled (a body moved into its index since, by remove(), is not that body).
  struct SettledHit {
    std::size_t body;
    int event;
    std::array<T, 3> position;
    bool operator<(const SettledHit& o) const { return body != o.body ? body < o.body : event < o.event; }
  };
  std::vector<SettledHit> settled_hits_;  // sorted by body, then event
  AlignedArray<T> acc_[6];  // settle: the accelerations at both ends
  std::array<AlignedArray<T>, 13> end_state_, end_rates_;  // a rigid settle: the step's end
};

// Whatever ends a call, its hits end in order (EventWatch::finish, up to its stop).
template <class T>
struct OrderedHits {
  EventWatch<T>& events;
  ~OrderedHits() { events.finish(events.stop_time()); }
};

extern template class EventWatch<float>;
extern template class EventWatch<double>;

}  // namespace kinema
