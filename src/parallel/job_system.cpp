#include "kinema/job_system.hpp"

#include "kinema/error.hpp"
#include "parallel/cores.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

#if defined(__x86_64__)
#include <immintrin.h>
#endif
#if defined(__linux__)
#include <sched.h>
#include <unistd.h>
#endif

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

// ThreadSanitizer cannot see the synchronisation inside an uninstrumented libtbb (Debian's),
// so the hand-offs below are annotated: without that every parallel step would be reported
// as a race, and with it real races in kinema code still are (tools/test --sanitize).
#if defined(__SANITIZE_THREAD__)
#define KINEMA_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define KINEMA_TSAN 1
#endif
#endif
#if defined(KINEMA_TSAN)
extern "C" void __tsan_acquire(void* address);
extern "C" void __tsan_release(void* address);
#endif

namespace kinema {
namespace {

#if defined(KINEMA_TSAN)
void tsan_acquire(const void* address) { __tsan_acquire(const_cast<void*>(address)); }
void tsan_release(const void* address) { __tsan_release(const_cast<void*>(address)); }
#else
void tsan_acquire(const void*) {}
void tsan_release(const void*) {}
#endif

}  // namespace

// The process's, not the current arena's: called from inside one of kinema's arenas (a
// callback making a stepper), the arena's concurrency counts its host slots.
unsigned hardware_threads() {
  return unsigned(std::max(1, tbb::info::default_concurrency()));
}

namespace {

// The default job systems' spin: WorkerSpin's own, or KINEMA_WORKER_SPIN_US microseconds
// after a job (a machine shared with other work, a test run).
WorkerSpin default_spin() {
  WorkerSpin spin;
  const char* text = std::getenv("KINEMA_WORKER_SPIN_US");
  if (text == nullptr) return spin;
  constexpr long kMost = 10'000'000;
  long us = -1;
  const char* end = text + std::strlen(text);
  const auto [stop, error] = std::from_chars(text, end, us);
  if (error != std::errc() || stop != end || us < 0 || us > kMost) {
    throw Error("KINEMA_WORKER_SPIN_US: '" + std::string(text) + "' is not a whole number of microseconds from 0 to " +
                std::to_string(kMost));
  }
  spin.after_job = std::chrono::microseconds(us);
  return spin;
}

}  // namespace

JobSystem& default_job_system(unsigned threads) {
  static std::mutex guard;
  // Never destroyed: arenas torn down during static destruction can outlive oneTBB's own
  // globals. Reachable to the end, so leak checkers do not count them.
  static auto* systems = new std::map<unsigned, std::unique_ptr<TbbJobSystem>>;
  const unsigned n = threads == 0 ? hardware_threads() : threads;
  const std::lock_guard lock(guard);
  auto& system = (*systems)[n];
  if (!system) system = std::make_unique<TbbJobSystem>(n, default_spin());
  return *system;
}

SerialJobSystem& calling_thread_jobs() {
  static SerialJobSystem serial;  // stateless: shared freely
  return serial;
}

JobHandle SerialJobSystem::enqueue(RangeTask task, std::size_t item_count, std::size_t,
                                   void* context) {
  if (item_count > 0) task(0, item_count, 0, context);
  return nullptr;
}

namespace {

// The chunks [front, back) of one worker's slice not yet claimed, packed in one word so that
// a single compare-exchange claims from either end.
struct alignas(64) Slice {
  std::atomic<std::uint64_t> chunks{0};

  void reset(std::uint32_t front, std::uint32_t back) {
    chunks.store(std::uint64_t(back) << 32 | front, std::memory_order_relaxed);
  }

  // The owner claims from the front, a thief from the back. Relaxed is enough: the slices
  // are published by spawning the workers' tasks and joined by waiting for them.
  bool claim(bool from_front, std::uint32_t& chunk) {
    std::uint64_t seen = chunks.load(std::memory_order_relaxed);
    std::uint64_t next;
    do {
      const auto front = std::uint32_t(seen), back = std::uint32_t(seen >> 32);
      if (front >= back) return false;
      chunk = from_front ? front : back - 1;
      next = from_front ? seen + 1 : (seen & 0xffffffffu) | std::uint64_t(back - 1) << 32;
    } while (!chunks.compare_exchange_weak(seen, next, std::memory_order_relaxed));
    return true;
  }
};

constexpr unsigned kMaxSlices = 64;

// One call's items, cut into one contiguous slice per worker. A worker runs its own slice
// front to back, so across steps it meets the same bodies, in its own cache. Then it takes
// chunks from the backs of the other slices, so a worker that joins late or is slowed down
// costs only the chunks it did not get to. (Alternating the direction from call to call,
// to start on the freshest bodies, made steps at 1M bodies slower: the kernels prefetch
// ahead in address order, so a backward walk starts each block cold.)
class SliceSchedule {
 public:
  SliceSchedule(RangeTask task, std::size_t items, std::size_t min_range, unsigned workers,
                void* context)
      : task_(task), context_(context), items_(items) {
    constexpr std::size_t kMaxChunks = std::numeric_limits<std::uint32_t>::max();
    grain_ = std::max({min_range, items / kMaxChunks + 1});  // so that chunks fit 32 bits
    const std::size_t chunks = items / grain_ + (items % grain_ != 0);
    // A long min_range caps the workers a job wants: no helper is woken for an empty slice.
    slices_ = unsigned(std::min<std::size_t>({workers, kMaxSlices, chunks}));
    for (unsigned s = 0; s < slices_; ++s) {
      slice_[s].reset(std::uint32_t(chunks * s / slices_), std::uint32_t(chunks * (s + 1) / slices_));
    }
  }

  unsigned slices() const { return slices_; }
  // The core its caller posted it from (-1: unknown).
  int caller_cpu() const { return caller_cpu_; }

  // Workers that took the job and have finished with it (their last access to it).
  void finished() { done_.fetch_add(1, std::memory_order_release); }
  unsigned done() const { return done_.load(std::memory_order_acquire); }

  void run(unsigned worker) {
    const unsigned home = worker % slices_;
    drain(slice_[home], true, worker);
    for (unsigned k = 1; k < slices_; ++k) drain(slice_[(home + k) % slices_], false, worker);
  }

 private:
  void drain(Slice& slice, bool from_front, unsigned worker) {
    std::uint32_t chunk;
    while (slice.claim(from_front, chunk)) {
      const std::size_t begin = std::size_t(chunk) * grain_;
      task_(begin, std::min(items_, begin + grain_), worker, context_);
    }
  }

  RangeTask task_;
  void* context_;
  std::size_t items_;
  std::size_t grain_;
  unsigned slices_;
  int caller_cpu_ = detail::current_cpu();
  std::array<Slice, kMaxSlices> slice_;
  std::atomic<unsigned> done_{0};
};

// The mailbox of one worker's task (see TbbJobSystem): whether the task runs, and the job
// posted to it. A caller posts only to a task that waits or is gone, takes back a job no
// task took, and waits only for a task running its job, so no call waits for a sleeping
// thread and calls from several host threads never wait in a cycle.
struct alignas(64) Mailbox {
  static constexpr std::uintptr_t kGone = 0;    // no task: posting starts one
  static constexpr std::uintptr_t kReady = 1;   // the task spins for a job
  static constexpr std::uintptr_t kAsleep = 2;  // the task sleeps until notified
  static constexpr std::uintptr_t kBusy = 3;    // the task runs a job
  std::atomic<std::uintptr_t> word{kGone};      // or the SliceSchedule* posted
  std::mutex mutex;                             // for the sleep only
  std::condition_variable posted;
};

bool is_job(std::uintptr_t word) { return word > Mailbox::kBusy; }

using Clock = std::chrono::steady_clock;

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

std::int64_t ns(std::chrono::microseconds t) { return std::chrono::nanoseconds(t).count(); }

void pause_cpu() {
#if defined(__x86_64__)
  _mm_pause();
#endif
}

// What the workers' tasks share with the job system. The tasks hold it too: a task that
// oneTBB starts only after the job system is gone finds it closing and ends.
struct Workforce {
  Workforce(unsigned threads, WorkerSpin spin) : helpers(std::min(threads, kMaxSlices)), spin(spin) {}

  unsigned helpers;  // workers with a task of their own (a job has at most kMaxSlices slices)
  WorkerSpin spin;
  std::array<Mailbox, kMaxSlices> box{};
  std::atomic<unsigned> pending{0};  // tasks started and not yet ended (queued or running)
  std::atomic<bool> closing{false};
  std::atomic<unsigned> started{0};  // tasks that have begun, ever
  std::atomic<std::int64_t> spun_ns{0};

  void serve(unsigned worker, bool spin_first);
  std::uintptr_t spin_until(const Mailbox& m, std::int64_t until);
  std::uintptr_t sleep(Mailbox& m);
  bool take_back(unsigned worker, SliceSchedule* job);
  void notify(Mailbox& m);
};

}  // namespace

struct TbbJobSystem::Arena {
  Arena(unsigned threads, WorkerSpin spin)
      : arena(int(threads), 1), threads(threads), work(std::make_shared<Workforce>(threads, spin)) {}
  void start(unsigned worker, bool spin_first);
  bool post(unsigned worker, SliceSchedule* job);

  tbb::task_arena arena;
  unsigned threads;
  std::shared_ptr<Workforce> work;
};

namespace {

// The task of worker `worker` (1 .. threads - 1): jobs as they are posted, until none came
// for spin.linger. The copy oneTBB keeps of it publishes the set-up (annotated: the hand-off
// is inside an uninstrumented libtbb).
class WorkerTask {
 public:
  WorkerTask(std::shared_ptr<Workforce> work, unsigned worker, bool spin_first)
      : work_(std::move(work)), worker_(worker), spin_first_(spin_first) {}
  WorkerTask(const WorkerTask& other) : work_(other.work_), worker_(other.worker_), spin_first_(other.spin_first_) {
    tsan_release(this);
  }
  WorkerTask(WorkerTask&& other) noexcept
      : work_(std::move(other.work_)), worker_(other.worker_), spin_first_(other.spin_first_) {
    tsan_release(this);
  }
  WorkerTask& operator=(const WorkerTask&) = delete;

  void operator()() const {
    tsan_acquire(this);
    work_->started.fetch_add(1, std::memory_order_relaxed);
    work_->serve(worker_, spin_first_);
    work_->pending.fetch_sub(1);
  }

 private:
  std::shared_ptr<Workforce> work_;
  unsigned worker_;
  bool spin_first_;  // as after a job (woken); else straight to sleep (started ahead)
};

}  // namespace

void TbbJobSystem::Arena::start(unsigned worker, bool spin_first) {
  work->pending.fetch_add(1);
  try {
    arena.enqueue(WorkerTask(work, worker, spin_first));
  } catch (...) {
    work->pending.fetch_sub(1);
    throw;
  }
}

// Posts a job to a worker whose task waits or is gone (starting a task then, waking it if it
// sleeps); false when the worker is busy with another caller's job.
bool TbbJobSystem::Arena::post(unsigned worker, SliceSchedule* job) {
  Mailbox& m = work->box[worker];
  const auto posted = reinterpret_cast<std::uintptr_t>(job);
  std::uintptr_t seen = m.word.load(std::memory_order_relaxed);
  while (seen <= Mailbox::kAsleep) {
    const std::uintptr_t was = seen;
    if (!m.word.compare_exchange_weak(seen, posted, std::memory_order_acq_rel)) continue;
    if (was == Mailbox::kGone) {
      try {
        start(worker, true);
      } catch (...) {  // no task will take the job: the mailbox is as it was
        m.word.store(Mailbox::kGone, std::memory_order_release);
        throw;
      }
    }
    if (was == Mailbox::kAsleep) work->notify(m);
    return true;
  }
  return false;
}

void Workforce::serve(unsigned worker, bool spin_first) {
  Mailbox& m = box[worker];
  std::int64_t idle_since = now_ns() - (spin_first ? 0 : ns(spin.after_job));
  for (;;) {
    std::uintptr_t job = spin_until(m, idle_since + ns(spin.after_job));
    if (!is_job(job)) {
      job = sleep(m);
      if (job == Mailbox::kAsleep) {  // lingered long enough, or the job system closes
        if (m.word.compare_exchange_strong(job, Mailbox::kGone, std::memory_order_acq_rel)) return;
      }
      idle_since = now_ns();  // woken: ready as after a job
      if (!is_job(job)) continue;
    }
    if (!m.word.compare_exchange_strong(job, Mailbox::kBusy, std::memory_order_acq_rel)) continue;  // taken back
    auto* schedule = reinterpret_cast<SliceSchedule*>(job);
    // The kernel may wake a sleeping worker on its waker's core; its spin there would then hold
    // that core, caller and all, until the next scheduler tick (4 ms on a 2-vCPU guest, where
    // the first call handed to a woken worker took 0.8-4.5 ms in nine fresh processes of ten,
    // the worker always on its caller's core). So it moves first.
    if (schedule->caller_cpu() >= 0 && detail::current_cpu() == schedule->caller_cpu()) {
      detail::leave_core(schedule->caller_cpu());
    }
    schedule->run(worker);
    schedule->finished();  // the caller may return from here on
    m.word.store(Mailbox::kReady, std::memory_order_release);
    idle_since = now_ns();
  }
}

// Spins until a job is posted, the time `until` or the job system closes; counts the spin.
std::uintptr_t Workforce::spin_until(const Mailbox& m, std::int64_t until) {
  const std::int64_t begin = now_ns();
  std::int64_t t = begin;
  std::uintptr_t word = m.word.load(std::memory_order_acquire);
  if (t >= until) return word;
  for (unsigned k = 1; !is_job(word) && t < until && !closing.load(std::memory_order_relaxed); ++k) {
    pause_cpu();
    if (k % 64 == 0) t = now_ns();
    word = m.word.load(std::memory_order_acquire);
  }
  spun_ns.fetch_add(now_ns() - begin, std::memory_order_relaxed);
  return word;
}

// Sleeps until a job is posted (notified), for at most spin.linger; kAsleep if none came.
std::uintptr_t Workforce::sleep(Mailbox& m) {
  std::uintptr_t ready = Mailbox::kReady;
  if (!m.word.compare_exchange_strong(ready, Mailbox::kAsleep, std::memory_order_acq_rel)) return ready;
  std::unique_lock lock(m.mutex);
  m.posted.wait_for(lock, spin.linger, [&] {
    return closing.load(std::memory_order_relaxed) || m.word.load(std::memory_order_acquire) != Mailbox::kAsleep;
  });
  return m.word.load(std::memory_order_acquire);
}

void Workforce::notify(Mailbox& m) {
  { const std::lock_guard lock(m.mutex); }  // not between the sleeper's test and its wait
  m.posted.notify_one();
}

// Takes back a job its worker did not take; false when the worker took it (the caller then
// waits for the job's own count of finished workers, never for another caller's job).
bool Workforce::take_back(unsigned worker, SliceSchedule* job) {
  auto posted = reinterpret_cast<std::uintptr_t>(job);
  // A task that had gone asleep and was woken for the job finds it gone: it spins again.
  return box[worker].word.compare_exchange_strong(posted, Mailbox::kReady, std::memory_order_acq_rel);
}

// The workers' tasks start at once, and the constructor waits (at most 20 ms) until they
// have: oneTBB takes 1 to 7 ms to start its threads on these machines, which would
// otherwise fall on the first steps.
TbbJobSystem::TbbJobSystem(unsigned threads, WorkerSpin spin)
    : arena_(std::make_unique<Arena>(threads == 0 ? hardware_threads() : threads, spin)) {
  Workforce& work = *arena_->work;
  for (unsigned w = 1; w < work.helpers; ++w) {
    work.box[w].word.store(Mailbox::kReady);
    arena_->start(w, false);  // asleep until the first job: nothing spins ahead of it
  }
  // No more tasks start at once than oneTBB has worker threads.
  const auto threads_of_tbb = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
  const unsigned expected = unsigned(std::min<std::size_t>(work.helpers - 1, threads_of_tbb - 1));
  const std::int64_t until = now_ns() + 20'000'000;
  while (work.started.load() < expected && now_ns() < until) std::this_thread::yield();
}

// Waits for the workers' tasks to end, those oneTBB has not started yet too (they end as
// they start), for at most 5 s: a task that oneTBB never starts (a host that capped its
// threads) keeps the shared state alive, and ends whenever it does start.
TbbJobSystem::~TbbJobSystem() {
  Workforce& work = *arena_->work;
  work.closing.store(true);
  for (unsigned w = 1; w < work.helpers; ++w) work.notify(work.box[w]);
  const std::int64_t until = now_ns() + 5'000'000'000;
  while (work.pending.load() > 0 && now_ns() < until) std::this_thread::yield();
}

unsigned TbbJobSystem::worker_count() const { return arena_->threads; }

double TbbJobSystem::spin_seconds() const { return double(arena_->work->spun_ns.load()) * 1e-9; }

// Starts the tasks that are gone and wakes those asleep: they spin as after a job.
void TbbJobSystem::wake() {
  Workforce& work = *arena_->work;
  for (unsigned w = 1; w < work.helpers; ++w) {
    Mailbox& m = work.box[w];
    std::uintptr_t seen = m.word.load(std::memory_order_relaxed);
    if (seen == Mailbox::kGone && m.word.compare_exchange_strong(seen, Mailbox::kReady)) arena_->start(w, true);
    if (seen == Mailbox::kAsleep && m.word.compare_exchange_strong(seen, Mailbox::kReady)) work.notify(m);
  }
}

// The calling thread runs the first slice, then takes what is left of the others; the
// workers' tasks take theirs as they come. Returns when every worker that took the job is
// done with it, also when posting to a later worker throws.
JobHandle TbbJobSystem::enqueue(RangeTask task, std::size_t item_count, std::size_t min_range,
                                void* context) {
  if (item_count == 0) return nullptr;
  SliceSchedule schedule(task, item_count, min_range, arena_->threads, context);
  struct Posts {
    Workforce& work;
    SliceSchedule& schedule;
    std::array<bool, kMaxSlices> posted{};
    ~Posts() {
      unsigned taken = 0;
      for (unsigned w = 1; w < schedule.slices(); ++w) taken += posted[w] && !work.take_back(w, &schedule);
      for (unsigned k = 1; schedule.done() < taken; ++k) k % 64 == 0 ? std::this_thread::yield() : pause_cpu();
    }
  } posts{*arena_->work, schedule};
  for (unsigned w = 1; w < schedule.slices(); ++w) posts.posted[w] = arena_->post(w, &schedule);
  schedule.run(0);
  return nullptr;
}

}  // namespace kinema

namespace kinema::detail {

int current_cpu() {
#if defined(__linux__)
  return sched_getcpu();
#else
  return -1;
#endif
}

namespace {

#if defined(__linux__)
// The calling thread's allowed cores, in a set sized for the machine (CPU_ALLOC: more than
// 1024 cores too); nullptr where the system refuses.
struct CoreSet {
  cpu_set_t* set = nullptr;
  std::size_t bytes = 0;
  int cores = 0;
  CoreSet() {
    const long configured = sysconf(_SC_NPROCESSORS_CONF);
    for (int n = int(std::max(configured, 1024L)); n <= (1 << 20); n *= 2) {
      set = CPU_ALLOC(n);
      bytes = CPU_ALLOC_SIZE(n);
      cores = n;
      if (set == nullptr) return;
      if (sched_getaffinity(0, bytes, set) == 0) return;
      CPU_FREE(set);
      set = nullptr;
      if (errno != EINVAL) return;
    }
  }
  ~CoreSet() {
    if (set != nullptr) CPU_FREE(set);
  }
  CoreSet(const CoreSet&) = delete;
  CoreSet& operator=(const CoreSet&) = delete;
};
#endif

}  // namespace

bool leave_core(int cpu) {
#if defined(__linux__)
  CoreSet allowed;
  if (allowed.set == nullptr || cpu < 0 || cpu >= allowed.cores || !CPU_ISSET_S(cpu, allowed.bytes, allowed.set)) {
    return false;
  }
  cpu_set_t* elsewhere = CPU_ALLOC(allowed.cores);
  if (elsewhere == nullptr) return false;
  std::memcpy(elsewhere, allowed.set, allowed.bytes);
  CPU_CLR_S(cpu, allowed.bytes, elsewhere);
  const bool narrowed = CPU_COUNT_S(allowed.bytes, elsewhere) > 0 && sched_setaffinity(0, allowed.bytes, elsewhere) == 0;
  CPU_FREE(elsewhere);
  if (!narrowed) return false;
  const bool moved = current_cpu() != cpu;  // the kernel moves the thread before it returns
  // The allowed cores back, twice if need be: a thread left narrowed would never use `cpu`.
  if (sched_setaffinity(0, allowed.bytes, allowed.set) != 0) sched_setaffinity(0, allowed.bytes, allowed.set);
  return moved;
#else
  (void)cpu;
  return false;
#endif
}

}  // namespace kinema::detail
