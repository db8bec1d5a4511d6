#pragma once
// Stepper: advances a ParticleSet under a ForceModel with a Method.
//
// It picks the path once, at construction: the fused path (one pass per step, all stages
// in registers) when the model is local and the method built in; the block path (every stage
// of a slice of bodies in cache, callbacks between stages) for callbacks or a method of the
// user's own without coupled terms; else the staged path (one parallel pass per stage).
// Forces applied to single bodies (ParticleSet::apply_force, ...) act on every path. All scratch is allocated at construction or at the first
// step that sees a larger body count (see reserve); a step allocates nothing, starts no
// thread and throws only on a bad argument, before any body moves; under a finiteness guard,
// a NonFiniteError with the bodies put back to the last finite state; or for what happens
// inside it (user code that throws, a host's enqueue that throws, an event function's NaN,
// an implicit solve whose sums overflow), with the bodies and the clock as before the step
// (for an event function under step() and advance(), as before the call: kinema/events.hpp;
// under a finiteness guard, as before the call too: the steps before it were not checked;
// but where the guard checks one step at a time, searching for the step that made a value
// not finite or watching stop events, as after the last step it checked).

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "kinema/events.hpp"
#include "kinema/forces.hpp"
#include "kinema/isa.hpp"
#include "kinema/job_system.hpp"
#include "kinema/methods.hpp"
#include "kinema/stability.hpp"

namespace kinema {

// How an implicit method's linear solves are preconditioned. Each choice gives its own bits
// (the same on every thread count and ISA); a checkpoint resumes under the one it was taken with.
enum class ImplicitPreconditioner : std::uint8_t {
  automatic,  // multigrid for spring networks over kMultigridBodies bodies or more, else Jacobi
  jacobi,     // each body's diagonal: no setup, iterations grow as gamma h |lambda|
  // Aggregation multigrid (one V-cycle an iteration, about three times an iteration's cost):
  // iterations that grow far more slowly with the springs' stiffness times the step.
  multigrid,
};
// Networks reaching fewer bodies than this solve in few enough iterations that a V-cycle's
// passes cost more than they save.
inline constexpr std::size_t kMultigridBodies = 1024;
// Whether solves over a spring network reaching `network_bodies` (max index + 1) take multigrid.
inline bool takes_multigrid(ImplicitPreconditioner p, std::size_t network_bodies) {
  if (network_bodies == 0) return false;
  return p == ImplicitPreconditioner::multigrid ||
         (p == ImplicitPreconditioner::automatic && network_bodies >= kMultigridBodies);
}

// What a stepper does about state that stops being finite (a step past the stability
// limit, a force that returns NaN).
enum class FiniteGuard {
  off,    // nothing: the caller checks (all_finite, first_non_finite) if it wants to
  // When a step leaves a value that is not finite, the bodies and the clock are put back to
  // the step before it and a NonFiniteError names the step, the body and the field. On the
  // fused particle path a call steps each block into a second copy of px .. vz while the
  // block is in cache and scans it there; when every value is finite the set takes that
  // copy and gives its own arrays for the next call (its px() .. vz() pointers change with
  // each call; inv_mass and the applied forces stay): the state once more in memory, no
  // more passes over it. Other paths keep a copy of the state a call starts from (two more
  // passes over it per call) and put it back.
  check,
  // check, and after every step each velocity longer than max_speed, and each rigid body's
  // angular velocity above max_angular_speed, is scaled down to that length. This changes
  // the physics (energy is lost) to keep a run going; steps then run one at a time.
  clamp,
};

enum class WorkerChoice { measured, all };

struct StepperOptions {
  Isa isa = Isa::automatic;
  // The host's job system; nullptr uses the process-wide default_job_system(threads)
  // (0: all hardware threads), shared with every other stepper that is given none.
  JobSystem* jobs = nullptr;
  unsigned threads = 0;
  // How many of the job system's workers a call uses. Results are the same bits for any
  // count, so by default the stepper times its own calls, as the host makes them (back to
  // back, or once a frame with the workers asleep in between), and uses the count that runs
  // them fastest for that kind and size of call: the calling thread alone, or 2 .. all
  // workers. Each is tried a few times at first use and again now and then (at most about 1%
  // of the time once settled). `all` hands every call to all workers (a host that wants its
  // own policy). A job system of one worker (a host's physics thread) gets every call either
  // way. In its first frames a host sees the options take turns, two calls at a time, until
  // each has three judged calls (the first after a switch is not judged: it pays the switch),
  // then the fastest (the default job system's threads have started when its constructor,
  // in the first stepper's, returns: see TbbJobSystem); an
  // option that lost is tried again after 8 calls, then 16, 32 ... as more samples confirm
  // it (at most every 4096), and a lower cost seen in two calls in a row is believed at
  // once, so a choice misjudged on a cold start is undone within tens of calls.
  WorkerChoice workers = WorkerChoice::measured;
  // Sets with fewer (real) bodies than this always run on the calling thread.
  std::size_t inline_below = 0;
  // Take the staged path even where the fused one applies (cross-checks, benchmarks).
  bool force_staged = false;
  // Scalar and SSE2 paths only (CPUs without FMA, or a forced isa): multiply then add
  // instead of an exact fused multiply-add. Faster there, but results then differ in the
  // last bits from the AVX2 and AVX-512 paths. Those always use their FMA units. (A build
  // configured with KINEMA_RELAXED_KERNELS=OFF has only the exact kernels: this selects them.)
  bool relaxed_fma = false;
  // Rigid bodies: renormalize orientation quaternions after each step. Off only to test
  // how a method lets |q| drift.
  bool renormalize_quaternions = true;
  FiniteGuard guard = FiniteGuard::off;
  // Implicit methods (implicit_euler, ros2): each stage's linear system is solved by
  // conjugate gradients until the residual is at most implicit_tolerance times the right
  // side's (0: 1e-3 for float, 1e-10 for double) or implicit_max_iterations have run (the
  // solve then stops where it is and ImplicitStats::unconverged counts it). A solve whose
  // sums overflow T (springs far too stiff for the step in this precision) throws
  // kinema::Error, the set and the clock as before the step.
  double implicit_tolerance = 0;
  int implicit_max_iterations = 1000;
  ImplicitPreconditioner implicit_preconditioner = ImplicitPreconditioner::automatic;
  double max_speed = 500;          // clamp: length units per second, finite and > 0
  double max_angular_speed = 50;   // clamp, rigid bodies: radians per second, finite and > 0
};

// A stepper's clock exactly as it counts (time() = origin + steps * h, each step k of a call
// at origin + (steps + k) h), and the step its last advance_to call proposed
// (AdaptiveStats::next_step; 0 before any): what a checkpoint keeps of a stepper.
struct StepperClock {
  double origin = 0;
  std::uint64_t steps = 0;
  double h = 0;  // the last step size, a value of T
  double proposed_step = 0;
};

// StepperOptions::implicit_tolerance 0 means this, in T. Float is what frame-rate scenes run
// in, where the step's own error dwarfs a solve's: on the shipped cloth at 1/60 s, 1e-3 moves
// the error against a fine rk4 run by under 2% under either method, with about half the
// iterations of 1e-5 (the library guide). Double keeps a tight solve for studies of accuracy.
template <class T>
inline constexpr double kDefaultImplicitTolerance = sizeof(T) == sizeof(float) ? 1e-3 : 1e-10;

// What an implicit method's steps solved since the stepper was made (or took a new model).
struct ImplicitStats {
  std::uint64_t solves = 0;      // linear systems (one per stage per step)
  std::uint64_t iterations = 0;  // conjugate-gradient iterations over all of them
  int max_iterations = 0;        // the most one solve took
  std::uint64_t unconverged = 0; // solves stopped by implicit_max_iterations
};

// `options` with every step run on the calling thread: no worker thread is involved.
inline StepperOptions on_calling_thread(StepperOptions options = {}) {
  options.jobs = &calling_thread_jobs();
  return options;
}

template <class T>
struct StepperAccess;  // src/step: what a checkpoint reads and writes of a stepper

template <class T>
class Stepper {
 public:
  // Throws kinema::Error for an invalid method or an unavailable ISA.
  Stepper(ForceModel<T> forces, const Method& method, StepperOptions options = {});
  // Shares `forces` (with another stepper, as a World's two do) instead of keeping a copy.
  Stepper(std::shared_ptr<const ForceModel<T>> forces, const Method& method,
          StepperOptions options = {});
  ~Stepper();
  Stepper(Stepper&&) noexcept;
  Stepper& operator=(Stepper&&) noexcept;

  // One step of size h (> 0, finite; else kinema::Error). Forces see t = time().
  void step(ParticleSet<T>& io_bodies, T h);
  // `steps` steps of size h; step k sees t = t_start + k h exactly (no running sum). On the
  // fused path each block of bodies takes all its steps while in cache (same bits as
  // calling step() `steps` times, far less memory traffic), so nothing can look at the set
  // between those steps: call step() for that. What user code throws leaves the set as
  // before the step that threw; time() counts the steps completed. kinema::Error (nothing
  // changed) when the clock's count of steps of this size would pass 2^64 (set_time moves it).
  void advance(ParticleSet<T>& io_bodies, T h, std::uint64_t steps);
  // The same, polling `stop` before each block of every pass of coupled terms (one N-body
  // step takes seconds at 32768 bodies) and of callbacks (on the block path, before each
  // block takes its steps of the call): once it returns true, the step under way is
  // abandoned, the set and time() as before it (under a guard: as before the call), and the
  // steps completed are returned (a stop event: the steps to it, the last cut at the event);
  // the call's applied forces are kept for the rest. `stop` may
  // be called from every worker at once. With local terms only a step costs a few
  // nanoseconds a body and nothing is polled: World::advance polls between short calls.
  std::uint64_t advance(ParticleSet<T>& io_bodies, T h, std::uint64_t steps, const StopRequest& stop);
  // With an embedded pair (bs3, dopri5): steps from time() to t_end choosing each step's
  // size, and returns what it took. A step whose error is too large is taken back (the bodies
  // as they were) and tried shorter; the next size comes from a PI controller (see
  // src/step/step_controller.hpp); the last step lands on t_end. A pair whose last stage is evaluated at
  // the new state (FSAL) reuses it as the next step's first. The accepted steps depend only
  // on the bodies and the tolerances: the same on every thread count and instruction set.
  // A candidate that is not finite is rejected like one too inaccurate (the finiteness guard
  // applies to step and advance; here nothing non-finite is ever accepted), so a blow-up ends
  // in the underflow error with the bodies at the last accepted step.
  // Throws kinema::Error for a method without a pair, bad tolerances, t_end before time(),
  // or a step that would underflow.
  AdaptiveStats advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances);
  // The same, returning early (AdaptiveStats::stopped) after the first accepted step at which
  // `stop` returns true; the next call to the same t_end goes on exactly from there.
  AdaptiveStats advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances,
                           const StopRequest& stop);
  // The same, with `interrupt` polled where `stop` is and besides inside each attempt, as
  // advance polls it (the attempt under way is taken back, its work lost: for signals, not
  // for pauses such as a checkpoint due, which would never let a long attempt finish) and
  // in the stable-step estimate of Tolerances::limit_to_stable_step.
  AdaptiveStats advance_to(ParticleSet<T>& io_bodies, double t_end, const Tolerances& tolerances,
                           const StopRequest& stop, const StopRequest& interrupt);
  // Rigid bodies: the same, with orientation and angular momentum: the fused path for a
  // built-in method and local terms, the rigid path for RigidCallbacks, point springs,
  // coupled terms (body springs, N-body gravity and spring pairs among the centres,
  // CoupledTerms) or another method. Use one stepper per body set: each keeps its own clock.
  void step(RigidBodySet<T>& io_bodies, T h);
  void advance(RigidBodySet<T>& io_bodies, T h, std::uint64_t steps);
  // With `stop` polled as for particles; returns the steps completed (a stop event: the
  // steps to it, the last cut at the event).
  std::uint64_t advance(RigidBodySet<T>& io_bodies, T h, std::uint64_t steps, const StopRequest& stop);
  // Error control for rigid bodies, as for particles, the error norm's mean taken over the
  // 13 components of each body: x, v, the orientation quaternion q (dimensionless: atol 1e-6
  // allows about 2e-6 rad of turn) and the world angular momentum L, all weighted by
  // atol + rtol max(|y_old|, |y_new|). Every stage is evaluated (no first stage reused); no
  // stop requests; Tolerances::limit_to_stable_step is refused (kinema::Error). Events are
  // watched on each accepted step, a stop event ending the call at it, as for particles.
  AdaptiveStats advance_to(RigidBodySet<T>& io_bodies, double t_end, const Tolerances& tolerances);
  // Throws the kinema::Error a step of size h would throw (h not positive and finite in T,
  // or h times the force parameters, a rigid body's point forces included, overflowing T;
  // for a Runge-Kutta method, h times the most its stages' weights add up to, about 25 for
  // dopri5: a stage's sum of rates must fit too), without touching any body. The steps of
  // advance_to, which its error control shrinks, are checked with h alone.
  void check_step_size(T h) const;
  // The accelerations (force / mass; 0 for bodies with inv_mass 0) the model gives the
  // bodies at time t, into out[0..2] (padded_size() each). Not for the inside of a frame:
  // the first call allocates what it needs.
  void accelerations(const ParticleSet<T>& bodies, double t, T* const out[3]);
  // The rates of rigid bodies' 13 state components at time t, into out[0..12] (padded_size()
  // each): x' = v (0..2), v' = force / mass (3..5), q' = (0, omega) q / 2 (6..9, w x y z),
  // L' = torque (10..12). Not for the inside of a frame: the first call allocates.
  void rates(const RigidBodySet<T>& bodies, double t, T* const out[13]);
  // A hint for a frame loop, called before step() or advance(): when the stepper's next call
  // of the kind it last made is to use workers, the job system is asked to wake them now
  // (JobSystem::wake), so that they may be awake when the call comes. Otherwise nothing
  // happens. TbbJobSystem's workers spin for 20 ms after each job (WorkerSpin), so in a
  // frame loop of 50 Hz and more they are ready anyway.
  void prepare();
  // Allocates the scratch of the stepper's paths (staged, block, rigid block) for up to
  // `bodies` bodies ahead of time.
  void reserve(std::size_t bodies);
  // Bytes the stepper holds for stepping: the staged and block paths' stage state, the
  // lowered spring network, the finiteness guard's copy of the state, and the scratch of the
  // accelerations probe once accelerations() (or advance_to's stable-step cap) has used it.
  std::size_t scratch_bytes() const;
  // Replaces the force model between steps (new gravity, wind, anchors, torques): checked
  // here, before anything changes (kinema::Error, the stepper as it was), with no new job
  // system. A model of local terms keeps the fused path. The clock goes on.
  void set_forces(ForceModel<T> forces);

  // Events (kinema/events.hpp) watched by every later step(), advance() and advance_to()
  // on a particle set whose model has built-in local terms only (any method): on the fused
  // path the kernels run the sign test themselves, elsewhere each step is scanned; only the
  // bodies that crossed are located. Rigid bodies under built-in local terms (no rigid
  // callback, point spring, body spring or coupled term) are watched too, by their centres'
  // values (each slice's fixed steps scanned in cache). A call that cannot watch them (a
  // model with callbacks or coupled terms) throws kinema::Error before any body moves. Under
  // advance_to a stop event ends the call at the event (the set and time() there; the next
  // call starts its step sizes afresh, as a first call does), and a throwing event function
  // takes back the step it scanned and its hits. An empty list watches nothing.
  // Throws kinema::Error for an invalid event (its index and field named).
  void set_events(EventOptions<T> events);
  // The hits of the last step(), advance() or advance_to() call, ordered by time, body and
  // event (the list grows as hits are found: a call with hits may allocate).
  const std::vector<EventHit<T>>& event_hits() const;
  // Whether the last call ended at a stop event: the set and time() are at its time.
  bool stopped_at_event() const;
  // An implicit method's linear solves since the stepper was made or took a new model (all
  // zero for other methods).
  const ImplicitStats& implicit_stats() const;

  // Simulated time: origin + steps_since_origin * h. Changing h moves the origin.
  double time() const;
  void set_time(double t);
  StepperClock clock() const;
  // kinema::Error (nothing changed) for a value that is not finite, an h or proposed step
  // that is negative, or an h that T cannot hold exactly (the origin may be any finite time).
  void set_clock(const StepperClock& clock);

  const Method& method() const;
  const ForceModel<T>& forces() const;
  const StepperOptions& options() const;
  Isa isa() const;           // the resolved instruction set the kernels use
  bool fused() const;        // true when particle steps take the fused single-pass path
  bool fused_rigid() const;  // true when rigid steps take the fused rigid kernels (else the rigid path)
  unsigned threads() const;  // workers of the job system in use
  // The worker count the stepper's measurements favour for its last kind and size of call
  // (0: the calling thread alone); what `workers = all` uses otherwise.
  unsigned chosen_workers() const;

 private:
  friend struct StepperAccess<T>;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The dominant eigenvalue of a force model's Jacobian at the bodies' state and time t
// (kinema/stability.hpp), from the accelerations of a stepper made with `options`. `stop`
// is polled before each force evaluation; once it returns true, kinema::Stopped is thrown.
template <class T>
StiffnessEstimate estimate_stiffness(const ParticleSet<T>& bodies, const ForceModel<T>& forces, double t = 0,
                                     int iterations = 120, StepperOptions options = on_calling_thread(),
                                     const StopRequest& stop = {});

// The same for rigid bodies, over their positions, velocities, orientations and angular
// momenta (kinema/stability.hpp): a stiff body-point spring makes a fast rotational mode.
template <class T>
StiffnessEstimate estimate_stiffness(const RigidBodySet<T>& bodies, const ForceModel<T>& forces, double t = 0,
                                     int iterations = 120, StepperOptions options = on_calling_thread(),
                                     const StopRequest& stop = {});

extern template class Stepper<float>;
extern template class Stepper<double>;
extern template StiffnessEstimate estimate_stiffness(const ParticleSet<float>&, const ForceModel<float>&, double,
                                                     int, StepperOptions, const StopRequest&);
extern template StiffnessEstimate estimate_stiffness(const ParticleSet<double>&, const ForceModel<double>&, double,
                                                     int, StepperOptions, const StopRequest&);
extern template StiffnessEstimate estimate_stiffness(const RigidBodySet<float>&, const ForceModel<float>&, double,
                                                     int, StepperOptions, const StopRequest&);
extern template StiffnessEstimate estimate_stiffness(const RigidBodySet<double>&, const ForceModel<double>&, double,
                                                     int, StepperOptions, const StopRequest&);

}  // namespace kinema
