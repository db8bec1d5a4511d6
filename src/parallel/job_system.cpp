#include "kinema/job_system.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <mutex>

#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

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

JobSystem& default_job_system(unsigned threads) {
  static std::mutex guard;
  // Never destroyed: arenas torn down during static destruction can outlive oneTBB's own
  // globals. Reachable to the end, so leak checkers do not count them.
  static auto* systems = new std::map<unsigned, std::unique_ptr<TbbJobSystem>>;
  const unsigned n = threads == 0 ? hardware_threads() : threads;
  const std::lock_guard lock(guard);
  auto& system = (*systems)[n];
  if (!system) system = std::make_unique<TbbJobSystem>(n);
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
  std::array<Slice, kMaxSlices> slice_;
};

// Slots kept for host threads. One: a worker looking for work picks victims at random among
// the arena's slots, so empty reserved slots slow every hand-off (bench/README.md has the
// figures). A host thread that finds no free slot has its call run by a thread of the arena
// while it waits. That hand-off happens inside
// uninstrumented libtbb, out of reach of the annotations, so under TSan each host thread of
// the tests keeps a slot of its own.
#if defined(KINEMA_TSAN)
constexpr int kHostSlots = 8;
#else
constexpr int kHostSlots = 1;
#endif

// Runs the slices of the calling worker. The copy TBB keeps in its task publishes the
// caller's writes (the bodies, the schedule, the task itself) to the worker that runs it.
class Helper {
 public:
  explicit Helper(SliceSchedule& schedule) : schedule_(&schedule) {}
  Helper(const Helper& other) : schedule_(other.schedule_) { tsan_release(this); }

  // The arena's slots: host threads in [0, kHostSlots), its workers after them. Here: the
  // calling thread 0, the workers 1 .. threads - 1, as the JobSystem contract says.
  static unsigned worker_index() {
    const int slot = std::max(0, tbb::this_task_arena::current_thread_index());
    return slot < kHostSlots ? 0 : unsigned(slot - kHostSlots + 1);
  }
  Helper& operator=(const Helper&) = delete;

  void operator()() const {
    tsan_acquire(this);
    schedule_->run(worker_index());
    tsan_release(schedule_);
  }

 private:
  SliceSchedule* schedule_;
};

}  // namespace

struct TbbJobSystem::Arena {
  explicit Arena(unsigned threads)
      : arena(int(threads) - 1 + kHostSlots, kHostSlots), threads(threads) {}
  tbb::task_arena arena;
  unsigned threads;
};

TbbJobSystem::TbbJobSystem(unsigned threads)
    : arena_(std::make_unique<Arena>(threads == 0 ? hardware_threads() : threads)) {}

TbbJobSystem::~TbbJobSystem() = default;

unsigned TbbJobSystem::worker_count() const { return arena_->threads; }

// An empty task per worker: a sleeping worker wakes to take it, then looks for more work for
// a while before it sleeps again, which is when the job should come.
void TbbJobSystem::wake() {
  for (unsigned w = 1; w < arena_->threads; ++w) arena_->arena.enqueue([] {});
}

JobHandle TbbJobSystem::enqueue(RangeTask task, std::size_t item_count, std::size_t min_range,
                                void* context) {
  if (item_count == 0) return nullptr;
  // Runs to completion here: the calling thread starts on its own slice at once; the arena's
  // workers pick up one task each. A task that no worker took before the caller got to it
  // finds its slice already taken and returns.
  SliceSchedule schedule(task, item_count, min_range, arena_->threads, context);
  arena_->arena.execute([&] {
    tbb::task_group helpers;
    for (unsigned s = 1; s < schedule.slices(); ++s) {
#if defined(KINEMA_TSAN)
      // defer builds the whole task (the Helper copy last, so its release covers the task's
      // other fields) before run hands it to a worker.
      helpers.run(helpers.defer(Helper{schedule}));
#else
      helpers.run(Helper{schedule});
#endif
    }
    Helper{schedule}();
    helpers.wait();
    tsan_acquire(&schedule);  // the helpers' writes
  });
  return nullptr;
}

}  // namespace kinema
