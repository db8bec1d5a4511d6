#pragma once
// Blocks: the unit of work. A set of n bodies is cut into blocks of kBlockBodies (the last
// one shorter); the cut never depends on the thread count, so neither do the results.

#include <algorithm>
#include <cstddef>

#include "kinema/job_system.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

struct Block {
  std::size_t begin, end;  // bodies [begin, end)
};

inline std::size_t block_count(std::size_t bodies) { return (bodies + kBlockBodies - 1) / kBlockBodies; }

inline Block block(std::size_t index, std::size_t bodies) {
  return {index * kBlockBodies, std::min((index + 1) * kBlockBodies, bodies)};
}

namespace detail {

template <class F>
struct BlockTask {
  F& fn;
  std::size_t bodies;

  static void run(std::size_t first, std::size_t last, unsigned, void* context) {
    const auto& self = *static_cast<const BlockTask*>(context);
    for (std::size_t b = first; b < last; ++b) self.fn(block(b, self.bodies));
  }
};

}  // namespace detail

// Calls fn(Block) for every block of `bodies` bodies: on the calling thread when the set is
// smaller than `inline_below`, the job system has one worker or there is one block; else as
// one job on `jobs`, which may run the blocks in any order on any worker.
template <class F>
void for_each_block(JobSystem& jobs, std::size_t inline_below, std::size_t bodies, F&& fn) {
  const std::size_t blocks = block_count(bodies);
  if (bodies < inline_below || jobs.worker_count() <= 1 || blocks <= 1) {
    for (std::size_t b = 0; b < blocks; ++b) fn(block(b, bodies));
    return;
  }
  detail::BlockTask<F> task{fn, bodies};
  jobs.wait(jobs.enqueue(&detail::BlockTask<F>::run, blocks, 1, &task));
}

}  // namespace kinema
