#pragma once
// Where a stepper's calls run: each on the worker count its own timings favour for that kind
// and size of call (worker_tuner.hpp), timed as it runs.

#include <bit>
#include <cstddef>
#include <cstdint>

#include "kinema/job_system.hpp"
#include "parallel/blocks.hpp"
#include "parallel/worker_tuner.hpp"

namespace kinema {

class MeasuredWorkers {
 public:
  // `all`: every call goes to every worker, untimed. Sets of fewer than `inline_below`
  // bodies, and sets of one block, always run on the calling thread.
  MeasuredWorkers(JobSystem& jobs, bool all, std::size_t inline_below)
      : jobs_(&jobs), all_(all), inline_below_(inline_below) {}

  // Runs fn(Workers) and times it: fn returns the body-steps it did. A call that throws is
  // not counted. `kind` (below 2^55) tells apart calls that cost differently per body-step:
  // each kind, power of two of the body count and single or many steps has its own timings.
  template <class Fn>
  void run(std::uint64_t kind, std::size_t bodies, std::uint64_t steps, Fn&& fn) {
    if (bodies < inline_below_ || block_count(bodies) <= 1) return void(fn(Workers{jobs_, 0}));
    if (all_) return void(fn(all_workers(*jobs_)));
    const std::uint64_t key =
        kind << 8 | std::uint64_t(std::bit_width(bodies)) << 1 | (steps > 1);
    WorkerTuner& tuner = tuners_.find(key, jobs_->worker_count());
    last_ = &tuner;
    const Workers workers{jobs_, tuner.choose()};
    const std::uint64_t begin = tuner_ticks();
    const double work = fn(workers);
    tuner.record(workers.count, tuner_ticks() - begin, work);
    favoured_ = tuner.best();
  }

  // Wakes the workers (JobSystem::wake) when the next call of the kind last made is to use
  // them.
  void prepare() const {
    const bool all = all_ && jobs_->worker_count() > 1;
    if (all || (last_ != nullptr && last_->choose() >= 2)) jobs_->wake();
  }

  // The worker count favoured for the last kind and size of call (0: the calling thread).
  unsigned favoured() const { return all_ ? jobs_->worker_count() : favoured_; }
  JobSystem& jobs() const { return *jobs_; }

 private:
  JobSystem* jobs_;
  bool all_;
  std::size_t inline_below_;
  WorkerTuners tuners_;
  const WorkerTuner* last_ = nullptr;  // of the last call timed
  unsigned favoured_ = 0;
};

}  // namespace kinema
