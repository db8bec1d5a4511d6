#pragma once
// Blocks: the unit of work. A set of n bodies is cut into blocks of kBlockBodies (the last
// one shorter); the cut never depends on the thread count, so neither do the results.

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>

#include "kinema/job_system.hpp"

namespace kinema {

struct Block {
  std::size_t begin, end;  // bodies [begin, end)
};

inline std::size_t block_count(std::size_t bodies) { return (bodies + kBlockBodies - 1) / kBlockBodies; }

inline Block block(std::size_t index, std::size_t bodies) {
  return {index * kBlockBodies, std::min((index + 1) * kBlockBodies, bodies)};
}

namespace detail {

// The blocks of one job. A block that throws (a user callback) stops the job: blocks not
// yet started are skipped, and the first exception is kept for the calling thread, so it
// never reaches the host's worker threads.
template <class F>
struct BlockTask {
  F& fn;
  std::size_t bodies;
  std::atomic<bool> failed{false};
  std::exception_ptr error;  // written once, by the block that set `failed`

  static void run(std::size_t first, std::size_t last, unsigned, void* context) {
    auto& self = *static_cast<BlockTask*>(context);
    for (std::size_t b = first; b < last && !self.failed.load(std::memory_order_relaxed); ++b) {
      try {
        self.fn(block(b, self.bodies));
      } catch (...) {
        if (!self.failed.exchange(true)) self.error = std::current_exception();
      }
    }
  }
};

}  // namespace detail

// Where a call's blocks run: as jobs on `jobs` that at most `count` workers can share (each
// range at least blocks / count long, or any length for all of its workers), or, for a count of 0, on the calling thread alone.
struct Workers {
  JobSystem* jobs = nullptr;
  unsigned count = 0;
};

// Whether `jobs` is one of kinema's own (serial, oneTBB), whose enqueue does not throw; a
// host's may, before it takes any range (see kinema/job_system.hpp).
inline bool enqueue_never_throws(const JobSystem* jobs) {
  return jobs == nullptr || dynamic_cast<const SerialJobSystem*>(jobs) || dynamic_cast<const TbbJobSystem*>(jobs);
}

// Every worker of the job system.
inline Workers all_workers(JobSystem& jobs) { return {&jobs, std::max(1u, jobs.worker_count())}; }

// Calls fn(Block) for every block of `bodies` bodies (a padded count): on the calling thread
// for a count of 0 or a single block; else as one job, which may run the blocks in any order
// on any worker. What fn throws comes out here, on the calling thread, once every range of
// the job has returned.
template <class F>
void for_each_block(const Workers& workers, std::size_t bodies, F&& fn) {
  const std::size_t blocks = block_count(bodies);
  if (workers.count == 0 || blocks <= 1) {
    for (std::size_t b = 0; b < blocks; ++b) fn(block(b, bodies));
    return;
  }
  // All of the job system's workers: any split (so a late worker leaves blocks to the rest).
  const bool all = workers.count >= workers.jobs->worker_count();
  const std::size_t min_range = all ? 1 : (blocks + workers.count - 1) / workers.count;
  detail::BlockTask<F> task{fn, bodies, {false}, nullptr};
  workers.jobs->wait(workers.jobs->enqueue(&detail::BlockTask<F>::run, blocks, min_range, &task));
  if (task.error) std::rethrow_exception(task.error);
}

}  // namespace kinema
