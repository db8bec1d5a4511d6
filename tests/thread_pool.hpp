#pragma once
// A small hand-made std::thread pool implementing kinema::JobSystem, standing in for a host
// engine's job system: ranges go to one queue, workers and waiting threads drain it. Each
// job counts its own ranges, so several host threads may use the pool at once and a task
// may wait for a job of its own (the waiting thread helps with whatever is queued).

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "kinema/job_system.hpp"

namespace kinema::test {

class ThreadPool final : public JobSystem {
 public:
  // `helping`: whether wait() runs queued ranges itself (a host's main thread would); when
  // false, only the pool's own threads run them (a dedicated physics thread).
  explicit ThreadPool(unsigned workers, bool helping = true) : helping_(helping) {
    // Worker ids stay in [0, worker_count()): 0 is the waiting thread when it helps.
    for (unsigned i = 0; i < workers; ++i) threads_.emplace_back([this, i] { work(i + (helping_ ? 1 : 0)); });
  }
  ~ThreadPool() override {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (auto& t : threads_) t.join();
  }

  unsigned worker_count() const override { return unsigned(threads_.size()) + (helping_ ? 1 : 0); }

  JobHandle enqueue(RangeTask task, std::size_t count, std::size_t min_range,
                    void* context) override {
    auto job = std::make_shared<Job>();
    // Deliberately small, uneven ranges: results must not depend on how work is cut.
    const std::size_t step = std::max<std::size_t>(min_range, 1);
    {
      std::lock_guard lock(mutex_);
      for (std::size_t b = 0; b < count;) {
        const std::size_t e = std::min(count, b + (b % 3 == 0 ? 2 * step : step));
        queue_.push_back({task, b, e, context, job});
        ++job->pending;
        b = e;
      }
      jobs_.push_back(job);
    }
    wake_.notify_all();
    return job.get();
  }

  void wait(JobHandle handle) override {
    std::shared_ptr<Job> job = take(handle);
    while (helping_ && !finished(*job) && run_one(0, false)) {
    }
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&] { return job->pending == 0; });
  }

  unsigned max_worker_seen() const { return max_worker_.load(); }
  // Ranges run by the pool's own threads, as against waiting threads.
  std::size_t ranges_on_pool_threads() const { return on_pool_.load(); }

 private:
  struct Job {
    std::size_t pending = 0;  // under mutex_
  };
  struct Range {
    RangeTask task;
    std::size_t begin, end;
    void* context;
    std::shared_ptr<Job> job;
  };

  std::shared_ptr<Job> take(JobHandle handle) {
    std::lock_guard lock(mutex_);
    auto it = std::find_if(jobs_.begin(), jobs_.end(), [&](const auto& j) { return j.get() == handle; });
    std::shared_ptr<Job> job = *it;
    jobs_.erase(it);
    return job;
  }

  bool finished(const Job& job) {
    std::lock_guard lock(mutex_);
    return job.pending == 0;
  }

  bool run_one(unsigned worker, bool pool_thread) {
    Range r;
    {
      std::lock_guard lock(mutex_);
      if (queue_.empty()) return false;
      r = queue_.front();
      queue_.pop_front();
    }
    r.task(r.begin, r.end, worker, r.context);
    if (pool_thread) ++on_pool_;
    unsigned seen = max_worker_.load();
    while (worker > seen && !max_worker_.compare_exchange_weak(seen, worker)) {
    }
    std::lock_guard lock(mutex_);
    if (--r.job->pending == 0) done_.notify_all();
    return true;
  }

  void work(unsigned worker) {
    for (;;) {
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [this] { return stop_ || !queue_.empty(); });
        if (stop_ && queue_.empty()) return;
      }
      run_one(worker, true);
    }
  }

  bool helping_;
  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  std::deque<Range> queue_;
  std::vector<std::shared_ptr<Job>> jobs_;
  bool stop_ = false;
  std::atomic<unsigned> max_worker_{0};
  std::atomic<std::size_t> on_pool_{0};
};

}  // namespace kinema::test
