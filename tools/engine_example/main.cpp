// An engine's frame loop around kinema, as an example and a test: a fixed timestep with
// interpolation for drawing, the engine's own worker threads, and bodies spawned and
// despawned while it runs. At the end the same events are replayed by advancing a second
// set directly; the two final states must be the same bits (exit code 0).
#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <thread>
#include <vector>

#include <kinema/kinema.hpp>

namespace {

// The engine's job system: a fork-join pool for one host thread (its frame loop), not
// called from its own tasks. A job is cut into one range per thread; the calling thread
// runs the first range itself, then waits for the others.
class ForkJoinPool final : public kinema::JobSystem {
 public:
  explicit ForkJoinPool(unsigned helpers) {
    for (unsigned w = 1; w <= helpers; ++w) threads_.emplace_back([this, w] { serve(w); });
  }
  ~ForkJoinPool() override {
    {
      std::lock_guard lock(mutex_);
      quit_ = true;
    }
    wake_.notify_all();
    for (auto& t : threads_) t.join();
  }
  unsigned worker_count() const override { return unsigned(threads_.size()) + 1; }

  kinema::JobHandle enqueue(kinema::RangeTask task, std::size_t items, std::size_t min_range,
                            void* context) override {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [this] { return running_ == 0; });  // one job at a time
    // Equal shares, each at least min_range items long (kinema caps a job's workers that way).
    const std::size_t shares = std::clamp<std::size_t>(items / std::max<std::size_t>(min_range, 1), 1, worker_count());
    job_ = {task, items, shares, context};
    const Job mine = job_;  // the helpers read job_ under the lock; this thread its copy
    running_ = threads_.size();
    ++generation_;
    wake_.notify_all();
    lock.unlock();
    run_share(mine, 0);
    return nullptr;
  }

  void wait(kinema::JobHandle) override {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [this] { return running_ == 0; });
  }

 private:
  struct Job {
    kinema::RangeTask task = nullptr;
    std::size_t items = 0;
    std::size_t shares = 1;
    void* context = nullptr;
  };

  void run_share(const Job& job, unsigned worker) {
    if (worker >= job.shares) return;
    const std::size_t n = job.shares, begin = job.items * worker / n, end = job.items * (worker + 1) / n;
    if (begin < end) job.task(begin, end, worker, job.context);
  }

  void serve(unsigned worker) {
    std::uint64_t seen = 0;
    for (;;) {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return quit_ || generation_ != seen; });
      if (quit_) return;
      seen = generation_;
      const Job job = job_;
      lock.unlock();
      run_share(job, worker);
      lock.lock();
      if (--running_ == 0) idle_.notify_all();
    }
  }

  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable wake_, idle_;
  Job job_;
  std::size_t running_ = 0;
  std::uint64_t generation_ = 0;
  bool quit_ = false;
};

// What happened at a step boundary, for the replay.
struct Event {
  std::uint64_t step;
  bool spawn;
  kinema::Vec3<float> position, velocity;  // spawn
  float mass;
  std::size_t index;                       // despawn
};

constexpr float kH = 1.0f / 60;

kinema::ForceModel<float> forces() {
  kinema::ForceModel<float> f;
  f.add(kinema::Gravity{{0, -9.81, 0}}).add(kinema::LinearDrag{0.05});
  return f;
}

// A burst of debris every 20 steps: 500 bodies flying up and out.
void spawn(kinema::ParticleSet<float>& set, std::uint64_t step, std::vector<Event>& log) {
  for (int k = 0; k < 500; ++k) {
    const float a = float(k) * 0.0125f, s = float(step % 7);
    const Event e{step, true, {s, 0, -s}, {std::sin(a) * 4, 12 + float(k % 9), std::cos(a) * 4}, 1 + float(k % 3), 0};
    set.add(e.position, e.velocity, e.mass);
    log.push_back(e);
  }
}

// Bodies that fell below the floor are despawned (swap with the last), highest first.
void despawn(kinema::ParticleSet<float>& set, std::uint64_t step, std::vector<Event>& log) {
  for (std::size_t i = set.size(); i-- > 0;) {
    if (set.py()[i] >= -20) continue;
    set.remove(i);
    log.push_back({step, false, {}, {}, 0, i});
  }
}

}  // namespace

int main() {
  ForkJoinPool pool(2);
  kinema::StepperOptions options;
  options.jobs = &pool;
  options.inline_below = 1024;  // small sets too go to the pool, as an engine might want
  kinema::Stepper<float> stepper(forces(), kinema::rk4, options);
  kinema::ParticleSet<float> current, previous, drawn;
  current.reserve(40000);
  std::vector<Event> log;
  kinema::FixedTimestep clock(kH, 4);
  std::uint64_t steps = 0;
  double drawn_height = 0;
  for (int frame = 0; frame < 600; ++frame) {
    const double frame_seconds = 0.011 + 0.002 * (frame % 5) + (frame == 300 ? 0.2 : 0);  // one hitch
    for (unsigned k = clock.steps_for(frame_seconds); k > 0; --k, ++steps) {
      if (steps % 20 == 0) spawn(current, steps, log);
      despawn(current, steps, log);
      previous = current;
      stepper.step(current, kH);
    }
    if (previous.size() != current.size()) previous = current;  // nothing stepped yet
    kinema::interpolate(previous, current, clock.alpha(), drawn);
    drawn_height = drawn.size() > 0 ? drawn.py()[0] : 0;
  }
  // The replay: the same events at the same step boundaries, advancing directly between them.
  kinema::ParticleSet<float> replay;
  kinema::Stepper<float> direct(forces(), kinema::rk4, kinema::on_calling_thread());
  std::uint64_t at = 0;
  for (const Event& e : log) {
    if (e.step > at) direct.advance(replay, kH, e.step - at), at = e.step;
    if (e.spawn) {
      replay.add(e.position, e.velocity, e.mass);
    } else {
      replay.remove(e.index);
    }
  }
  direct.advance(replay, kH, steps - at);
  bool same = replay.size() == current.size();
  for (std::size_t i = 0; same && i < current.size(); ++i) {
    same = replay.position(i) == current.position(i) && replay.velocity(i) == current.velocity(i);
  }
  std::printf("engine example: 600 frames, %llu steps (%llu dropped at the hitch), %zu bodies alive, "
              "%zu spawn and despawn events; body 0 drawn at y = %.3f; the direct replay %s\n",
              static_cast<unsigned long long>(steps), static_cast<unsigned long long>(clock.dropped_steps()),
              current.size(), log.size(), drawn_height, same ? "matches bit for bit" : "DIFFERS");
  return same ? 0 : 1;
}
