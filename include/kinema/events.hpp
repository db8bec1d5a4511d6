#pragma once
// Events: the moment inside a step at which a body's state crosses a surface or a threshold
// ("when does each body reach the floor?", "stop when anything is 10 km out").
//
// Each event is a value of one body's state whose sign change counts: n . x - offset for a
// plane, |x - point| - radius for a distance, |v| - speed for a speed, or a user function.
// After every step (Stepper::step, Stepper::advance) each body's value at both ends of the
// step is compared (by the fused kernels themselves for up to four built-in events); a body
// whose value changed sign the way the event asks is handed to a bracketing root finder on
// the step's dense output (kinema/dense_output.hpp: the cubic Hermite of both ends'
// positions, velocities and accelerations, with dopri5's own term after a dopri5 step),
// which finds the time to `time_tolerance`. The hit records the time, the body, the event and
// the state there. Events are watched on particle sets whose model has built-in local terms
// only, under any method, by step(), advance() and advance_to() (each accepted step), and on
// rigid bodies' centres under the same terms: a rigid body's values are its centre's, located
// on the Hermite for every method (dopri5 too, as RigidDenseOutput has it), and a stop settles
// all 13 components of every body (the orientation kept unit) on their Hermite.
//
// - A value that reaches zero exactly at a step's end counts in that step (its sign at the
//   next step's start is zero, neither above nor below): each crossing is found once.
// - A body whose value crosses and crosses back inside one step is not seen: the step is
//   too long for that event.
// - Hits are ordered by time, then body, then event: the same list on every ISA, thread
//   count and job system.
// - Action `stop`: the call ends at the first such hit. The set is then at that time (every
//   body on the dense output there) and so is the stepper's clock; hits later than it are
//   dropped. Steps with a stop event run one pass per step over the whole set. The next call
//   goes on from there: a crossing reported at the stop's time (the stop's own, another
//   body's or another event's) is not reported again where a body's state, rounded to T, lies
//   just short of it, the body starting from the state the stop left it in (a body that
//   ParticleSet::remove moved into its index is another body: its crossings are its own).

#include <cstddef>
#include <functional>
#include <string>
#include <variant>
#include <vector>

#include "kinema/bodies.hpp"

namespace kinema {

// The sign changes of an event's value that count: from above zero to zero or below
// (`down`: a plane crossed against its normal, a distance shrinking to the radius, a speed
// dropping to the threshold), from below zero to zero or above (`up`), or both.
enum class Crossing { down, up, either };

enum class EventAction {
  record,  // add the hit to the list, go on
  stop,    // record it and end the call there
};

// Value n . x - offset. n need not be unit length (the times are the same); not zero.
struct PlaneEvent {
  Vec3<double> normal{0, 1, 0};
  double offset = 0;
};

// Value |x - point| - radius (radius > 0): `down` is inward, `up` outward.
struct DistanceEvent {
  Vec3<double> point{};
  double radius = 1;
};

// Value |v| - speed (speed >= 0).
struct SpeedEvent {
  double speed = 1;
};

// What a user event sees: `count` real bodies from body `first`, positions and velocities
// offset to it, at time t.
template <class T>
struct EventBlock {
  std::size_t first = 0;
  std::size_t count = 0;
  double t = 0;
  const T *px, *py, *pz, *vx, *vy, *vz;
};

// Writes value[i] for each body i < count of the block. Like a ForceCallback it must be a
// pure function of the view, the time and the user's own read-only data, safe to call
// concurrently: it is called on each slice of bodies at both ends of every step, and on
// single interpolated states while a crossing is located. What it throws leaves the set and
// the clock as before the call under step() and advance() (a call with a user event keeps a
// copy of the state for that); under advance_to, as before the step it scanned (the steps
// accepted before that one stay, their hits too).
// A value that is NaN has no sign: it is refused as a throw is (kinema::Error naming the
// event, the body and the time), never taken as "no crossing".
template <class T>
using EventFunction = std::function<void(const EventBlock<T>& block, T* value)>;

template <class T>
struct Event {
  std::variant<PlaneEvent, DistanceEvent, SpeedEvent, EventFunction<T>> kind = PlaneEvent{};
  Crossing direction = Crossing::either;
  EventAction action = EventAction::record;
};

template <class T>
struct EventOptions {
  std::vector<Event<T>> events;
  // The located time is within this many seconds of the crossing of the dense output (the
  // root finder's bracket); 0: to round-off (4 ulps of the fraction of the step).
  double time_tolerance = 0;
};

template <class T>
struct EventHit {
  double time = 0;
  std::size_t body = 0;
  int event = 0;  // index into EventOptions::events
  Vec3<T> position{}, velocity{};  // of a rigid body: its centre's
};

}  // namespace kinema
