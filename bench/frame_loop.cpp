// Stepping as an engine does: one step per frame, the rest of the frame idle for the step's
// workers. Each iteration sleeps `gap` (0: back to back), then times one rk4 step. Rows:
//   threads:1   on the calling thread alone
//   default     default options: every hardware thread, the worker count measured
//   prepared    the same, with Stepper::prepare() called right before each step (timed too)
//   threads:2   both threads on every step (workers = all)
//   parallel_for  the peer: a plain tbb::parallel_for over the same blocks, same kernel
// The steppers step a few frames before the timing, as a game's first frames would.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

// The peer: the kernel's blocks handed to oneTBB's own parallel_for (global arena, auto
// partitioner), nothing of kinema's scheduling.
class ParallelForJobs final : public JobSystem {
 public:
  unsigned worker_count() const override { return hardware_threads(); }
  JobHandle enqueue(RangeTask task, std::size_t items, std::size_t min_range, void* context) override {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, items, min_range),
                      [&](const tbb::blocked_range<std::size_t>& r) { task(r.begin(), r.end(), 0, context); });
    return nullptr;
  }
  void wait(JobHandle) override {}
};

enum class Variant { one_thread, measured, prepared, two_threads, parallel_for };

StepperOptions options_for(Variant v) {
  static ParallelForJobs peer;
  StepperOptions o;
  switch (v) {
    case Variant::one_thread: return on_calling_thread();
    case Variant::measured:
    case Variant::prepared: return o;
    case Variant::two_threads: o.threads = 2; break;
    case Variant::parallel_for: o.jobs = &peer; break;
  }
  o.workers = WorkerChoice::all;
  return o;
}

constexpr int kWarmFrames = 24;

template <class T>
void frame_loop(benchmark::State& state, Variant variant, int gap_us) {
  const auto n = std::size_t(state.range(0));
  const ParticleSet<T>& initial = cached_particles<T>(n);
  ParticleSet<T> bodies = initial;
  Stepper<T> stepper(make_forces<T>(bench_scene(n)), rk4, options_for(variant));
  const auto gap = std::chrono::microseconds(gap_us);
  const auto frame = [&] {
    if (variant == Variant::prepared) stepper.prepare();
    stepper.step(bodies, T(kDt));
  };
  for (int k = 0; k < kWarmFrames; ++k) {
    std::this_thread::sleep_for(gap);
    frame();
  }
  std::vector<double> seconds;
  seconds.reserve(std::size_t(std::min<benchmark::IterationCount>(state.max_iterations, 1 << 22)));
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % kRestoreEvery == 0) restore(bodies, initial);
    if (gap_us > 0) std::this_thread::sleep_for(gap);
    const auto begin = std::chrono::steady_clock::now();
    frame();
    const auto end = std::chrono::steady_clock::now();
    seconds.push_back(std::chrono::duration<double>(end - begin).count());
    state.SetIterationTime(seconds.back());
  }
  require_finite(state, bodies);
  report_body_steps(state, double(n), particle_step_bytes<T>());
  state.counters["workers"] = stepper.chosen_workers();
  // The typical frame: a pre-empted step or a rare retry of another worker count moves the
  // mean (the time columns), not this.
  std::nth_element(seconds.begin(), seconds.begin() + std::ptrdiff_t(seconds.size() / 2), seconds.end());
  if (!seconds.empty()) state.counters["median_ns_per_body_step"] = seconds[seconds.size() / 2] * 1e9 / double(n);
}

// Iterations with a gap are counted, not timed to a minimum: the gaps are most of the time.
int iterations_for(int gap_us) { return gap_us >= 8000 ? 100 : gap_us >= 1000 ? 400 : 0; }

void register_all() {
  const std::pair<Variant, const char*> variants[] = {{Variant::one_thread, "threads:1"},
                                                      {Variant::measured, "default"},
                                                      {Variant::prepared, "prepared"},
                                                      {Variant::two_threads, "threads:2"},
                                                      {Variant::parallel_for, "parallel_for"}};
  for (int gap_us : {0, 1000, 8000}) {
    for (const auto& [variant, label] : variants) {
      const std::string suffix = "/gap_us:" + std::to_string(gap_us) + "/" + label;
      for (auto* b : {benchmark::RegisterBenchmark(("frame_loop/float" + suffix).c_str(), frame_loop<float>,
                                                   variant, gap_us),
                      benchmark::RegisterBenchmark(("frame_loop/double" + suffix).c_str(), frame_loop<double>,
                                                   variant, gap_us)}) {
        for (std::int64_t n : {1024, 4096, 16384, 65536, 100000, 1 << 20}) b->Arg(n);
        b->UseManualTime()->Unit(benchmark::kMicrosecond);
        if (iterations_for(gap_us) > 0) b->Iterations(iterations_for(gap_us));
      }
    }
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
