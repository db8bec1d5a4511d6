#include "kinema/job_system.hpp"

#include <algorithm>
#include <thread>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

namespace kinema {

unsigned hardware_threads() {
  return std::max(1, tbb::this_task_arena::max_concurrency());
}

JobHandle SerialJobSystem::enqueue(RangeTask task, std::size_t item_count, std::size_t,
                                   void* context) {
  if (item_count > 0) task(0, item_count, 0, context);
  return nullptr;
}

struct TbbJobSystem::Arena {
  explicit Arena(unsigned threads) : arena(int(threads)), threads(threads) {}
  tbb::task_arena arena;
  unsigned threads;
};

TbbJobSystem::TbbJobSystem(unsigned threads)
    : arena_(std::make_unique<Arena>(threads == 0 ? hardware_threads() : threads)) {}

TbbJobSystem::~TbbJobSystem() = default;

unsigned TbbJobSystem::worker_count() const { return arena_->threads; }

JobHandle TbbJobSystem::enqueue(RangeTask task, std::size_t item_count, std::size_t min_range,
                                void* context) {
  // Runs to completion here: the calling thread joins the arena's workers. Blocks cost the
  // same, so a static split (about one chunk per thread) has the least overhead.
  arena_->arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, item_count, std::max<std::size_t>(1, min_range)),
        [&](const tbb::blocked_range<std::size_t>& r) {
          const int worker = tbb::this_task_arena::current_thread_index();
          task(r.begin(), r.end(), unsigned(std::max(0, worker)), context);
        },
        tbb::static_partitioner{});
  });
  return nullptr;
}

}  // namespace kinema
