#pragma once
// How many workers a stepper call uses, chosen from the calls the stepper has timed.
//
// Results are the same bits for any worker count, so the choice may follow the clock. Each
// call is timed as the host runs it: back to back, or once per frame with the workers asleep
// in between, so waking them is part of what a count costs. The options are the calling
// thread alone and 2 .. all workers. Each is tried a few times at first use; then the
// fastest so far runs, and every other option is tried again once in a while, less often the
// slower it was and the more samples confirm it, so once settled retrying costs at most about
// 1% of the time, and a choice misjudged on a cold start is undone within tens of calls.

#include <array>
#include <cstddef>
#include <cstdint>

namespace kinema {

// A cheap monotonic tick count (the time-stamp counter on x86-64): only ratios are used.
std::uint64_t tuner_ticks();

class WorkerTuner {
 public:
  static constexpr unsigned kMaxOptions = 8;

  // Options for a job system of `workers` workers: 0 (the calling thread) and 2 .. workers
  // (at most kMaxOptions in all); with a single worker, 1 is the only option (a host's
  // physics thread keeps its jobs).
  explicit WorkerTuner(unsigned workers = 1);

  // The worker count for the next call (0: the calling thread).
  unsigned choose() const;
  // A call with `count` workers took `ticks` for `work` units (body-steps).
  void record(unsigned count, std::uint64_t ticks, double work);

  // The count that has been fastest (what choose returns between retries).
  unsigned best() const { return option_[best_].count; }

 private:
  struct Option {
    unsigned count = 0;
    unsigned samples = 0;
    double cost = 0;              // ticks per unit of work, a moving average
    double recent[2] = {0, 0};    // the last two samples, newest first
    std::uint64_t retry_at = 0;   // call number of the next retry
  };
  void update_best();
  unsigned index_of(unsigned count) const;

  std::array<Option, kMaxOptions> option_{};
  unsigned options_ = 1;
  unsigned best_ = 0;
  unsigned last_ = kMaxOptions;  // the option of the last call recorded (none yet)
  std::uint64_t calls_ = 0;
};

// Tuners for the kinds and sizes of call a stepper meets, the least recently used one
// replaced when a new kind appears. Fixed size: looking one up never allocates.
class WorkerTuners {
 public:
  // `key` tells calls apart that cost differently per body-step (path, size class).
  WorkerTuner& find(std::uint64_t key, unsigned workers);

 private:
  static constexpr std::size_t kSlots = 8;
  struct Slot {
    std::uint64_t key = 0;
    std::uint64_t used = 0;  // 0: empty
    WorkerTuner tuner{1};
  };
  std::array<Slot, kSlots> slot_{};
  std::uint64_t clock_ = 0;
};

}  // namespace kinema
