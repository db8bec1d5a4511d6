#pragma once
// How blocks of work run: the host engine's job system plugs in here.
//
// The contract, as kinema uses it:
// - A job is `item_count` items; an item is one block of kBlockBodies bodies (the last one
//   shorter). The host may split [0, item_count) into any ranges of at least `min_range` items
//   (except a last, shorter one), run them on any workers or inline (in `enqueue` or `wait`),
//   in any order: every block is computed the same way whoever runs it, so results do not
//   depend on the split or on the number of workers. kinema ignores the `worker` argument.
// - `min_range` is how kinema says how many workers a job is worth: a job meant for k
//   workers has min_range = item_count / k rounded up (1 for all of them). A host that
//   honours it wakes no more workers than that.
// - `wait` returns once every range of that job has returned; then kinema reads the
//   results. Tasks never throw into the host: what user code throws in a block is caught,
//   later blocks of the job are skipped, and it is rethrown by `wait`'s caller.
// - kinema may call `enqueue` and `wait` from several host threads at once (one job per
//   stepper call), and from inside one of the host's own tasks (a step run as a task): a
//   host whose `wait` helps run queued ranges, as oneTBB's and most engines' do, cannot
//   deadlock there.
// - With one worker (a host may give kinema one dedicated physics thread) every job goes to
//   the job system. With more, a stepper runs a call on the calling thread, without a job,
//   when its timings show that the workers do not pay (StepperOptions::workers); sets below
//   StepperOptions::inline_below, and sets of one block, always run that way.
// - `enqueue` may run ranges before it returns, but must not throw once it has taken any:
//   they point into the caller's stack frame until `wait` returns. A throw before that
//   leaves the set and the stepper's clock as before the step that threw, on every path.
// - A JobSystem must outlive every stepper that uses it.

#include <chrono>
#include <cstddef>
#include <memory>

namespace kinema {

// Bodies per block: the unit of work handed to the job system. Fixed, so the partition
// (and every result) is the same for any number of threads. 1024 bodies is 4 KiB per
// float array, 8 KiB per double array: a block's stage state stays in L1/L2.
inline constexpr std::size_t kBlockBodies = 1024;

// Processes items [begin, end). `worker` is in [0, worker_count()).
using RangeTask = void (*)(std::size_t begin, std::size_t end, unsigned worker, void* context);

// Opaque token returned by enqueue and handed back to wait.
using JobHandle = void*;

class JobSystem {
 public:
  virtual ~JobSystem() = default;
  // How many workers may run tasks at once (the calling thread counts if it helps).
  virtual unsigned worker_count() const = 0;
  virtual JobHandle enqueue(RangeTask task, std::size_t item_count, std::size_t min_range,
                            void* context) = 0;
  // Returns when every range of the job has run.
  virtual void wait(JobHandle job) = 0;
  // A hint that a job comes soon (Stepper::prepare): a job system whose workers sleep may
  // start waking them now, so that the job does not wait for them. Optional: by default
  // nothing happens.
  virtual void wake() {}
};

// Runs everything inline on the calling thread.
class SerialJobSystem final : public JobSystem {
 public:
  unsigned worker_count() const override { return 1; }
  JobHandle enqueue(RangeTask task, std::size_t item_count, std::size_t min_range,
                    void* context) override;
  void wait(JobHandle) override {}
};

// How long a TbbJobSystem's workers stay ready for the next job after one. A worker that
// sleeps is slow to come back on these virtual machines: tens of microseconds to wake, more
// than a small step takes. One that spins between the frames of a frame loop takes its
// share of the next step at once. Only workers that were posted a job (or woken by wake())
// spin: when a stepper's measured choice keeps its calls on the calling thread, nothing
// spins after after_job.
struct WorkerSpin {
  // After its job a worker spins this long for the next one: back-to-back steps, and frames
  // up to this long (20 ms: frame loops of 50 Hz and more). What it costs is up to one core
  // per worker while a frame loop runs (TbbJobSystem::spin_seconds counts it). Zero: a
  // worker sleeps at once after its job.
  std::chrono::microseconds after_job{20000};
  // Then it sleeps (no CPU; a job then waits for it to wake), and after this long without a
  // job its task ends, giving the thread back to oneTBB (the next job then waits for oneTBB
  // to hand it out again: up to milliseconds). Until then the thread is kinema's: oneTBB
  // work of the host's own gets the process's other oneTBB threads only (on a machine of
  // two hardware threads oneTBB has one worker thread in all), and so does another
  // TbbJobSystem in the process (a default_job_system of another thread count): its jobs run
  // on their callers alone, and its destructor waits for its tasks behind this one's.
  std::chrono::microseconds linger{100000};
};

// oneTBB with its own task_arena of `threads` threads (0: all hardware threads). The
// calling thread runs the first slice of each job; the arena's workers run the others, each
// in a task that stays to take the next job while `spin` says so: it spins, then sleeps,
// and ends after spin.linger without a job (until then one oneTBB worker thread is held by
// it). The tasks start with the job system, asleep, and its constructor waits for them (at
// most 20 ms): a first step does not pay for oneTBB's thread start. The arena is created
// once, not per step. A host's own job system never spins for kinema. enqueue returns once
// every worker that took its job is done with it, never waiting for another caller's job.
// A worker that takes a job on the core of the thread that posted it (Linux may wake a
// sleeping thread on its waker's core) moves to another of its allowed cores first, so that
// its spin after the job does not hold its caller's core until the next scheduler tick
// (milliseconds); it then gets back the affinity mask it had. A worker woken by wake() alone
// is not checked until it takes a job.
class TbbJobSystem final : public JobSystem {
 public:
  explicit TbbJobSystem(unsigned threads = 0, WorkerSpin spin = {});
  // Waits for its workers' tasks to end, at most 5 s (a task oneTBB has not started yet,
  // because another system's task holds its thread, ends whenever it starts)
  ~TbbJobSystem() override;
  TbbJobSystem(const TbbJobSystem&) = delete;
  TbbJobSystem& operator=(const TbbJobSystem&) = delete;

  unsigned worker_count() const override;
  JobHandle enqueue(RangeTask task, std::size_t item_count, std::size_t min_range,
                    void* context) override;
  void wait(JobHandle) override {}
  void wake() override;  // wakes the workers (starting ended tasks): they spin as after a job

  // CPU time the workers have spent waiting for a job while ready (spinning), in seconds,
  // since the job system was made: what the spin costs.
  double spin_seconds() const;

 private:
  struct Arena;
  std::unique_ptr<Arena> arena_;
};

// Number of hardware threads this process may use.
unsigned hardware_threads();

// The process-wide oneTBB job system of `threads` threads (0: all hardware threads), made at
// first use and kept for the life of the process: every stepper given no job system of its
// own shares it, so steppers never multiply arenas. Safe to call from any thread; the
// system it returns may be used from several host threads at once. Its workers spin as
// WorkerSpin says, or, where the environment variable KINEMA_WORKER_SPIN_US is set, that
// many microseconds after a job (0 to 10^7; kinema::Error otherwise).
JobSystem& default_job_system(unsigned threads = 0);

// A job system that runs everything on the calling thread, for any number of users.
SerialJobSystem& calling_thread_jobs();

}  // namespace kinema
