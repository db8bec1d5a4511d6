#pragma once
// A small hand-made std::thread pool implementing kinema::JobSystem, standing in for a host
// engine's job system: ranges go to a queue, workers and the waiting thread drain it.

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

#include "kinema/job_system.hpp"

namespace kinema::test {

class ThreadPool final : public JobSystem {
 public:
  explicit ThreadPool(unsigned workers) {
    for (unsigned i = 0; i < workers; ++i) threads_.emplace_back([this, i] { work(i + 1); });
  }
  ~ThreadPool() override {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (auto& t : threads_) t.join();
  }

  unsigned worker_count() const override { return unsigned(threads_.size()) + 1; }

  JobHandle enqueue(RangeTask task, std::size_t count, std::size_t min_range,
                    void* context) override {
    // Deliberately small, uneven ranges: results must not depend on how work is cut.
    const std::size_t step = std::max<std::size_t>(min_range, 1);
    {
      std::lock_guard lock(mutex_);
      for (std::size_t b = 0; b < count;) {
        const std::size_t e = std::min(count, b + (b % 3 == 0 ? 2 * step : step));
        queue_.push_back({task, b, e, context});
        ++pending_;
        b = e;
      }
    }
    wake_.notify_all();
    return this;
  }

  void wait(JobHandle) override {
    // The waiting thread helps, as a host's main thread would.
    while (run_one(0)) {
    }
    std::unique_lock lock(mutex_);
    done_.wait(lock, [this] { return pending_ == 0; });
  }

  unsigned max_worker_seen() const { return max_worker_.load(); }

 private:
  struct Range {
    RangeTask task;
    std::size_t begin, end;
    void* context;
  };

  bool run_one(unsigned worker) {
    Range r;
    {
      std::lock_guard lock(mutex_);
      if (queue_.empty()) return false;
      r = queue_.front();
      queue_.pop_front();
    }
    r.task(r.begin, r.end, worker, r.context);
    unsigned seen = max_worker_.load();
    while (worker > seen && !max_worker_.compare_exchange_weak(seen, worker)) {
    }
    std::lock_guard lock(mutex_);
    if (--pending_ == 0) done_.notify_all();
    return true;
  }

  void work(unsigned worker) {
    for (;;) {
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [this] { return stop_ || !queue_.empty(); });
        if (stop_ && queue_.empty()) return;
      }
      run_one(worker);
    }
  }

  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  std::deque<Range> queue_;
  std::size_t pending_ = 0;
  bool stop_ = false;
  std::atomic<unsigned> max_worker_{0};
};

}  // namespace kinema::test
