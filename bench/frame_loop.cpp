// Stepping as an engine does: one step per frame, the rest of the frame idle for the step's
// workers. Each frame sleeps `gap` (0: back to back), then times one rk4 step. Variants:
//   threads:1   on the calling thread alone
//   default     default options: every hardware thread, the worker count measured
//   prepared    the same, with Stepper::prepare() called right before each step (timed too)
//   threads:2   both threads on every step (workers = all)
//   parallel_for  the peer: a plain tbb::parallel_for over the same blocks, same kernel
// The steppers step a few frames before the timing, as a game's first frames would. The
// interleaved rows report the default job system's spinning per frame (spin_us_per_frame):
// the CPU time its workers spent ready for a job that had not come. Back to
// back, each variant is a row of its own; with gaps, the variants take turns in runs of 8
// frames in one row (a shared machine drifts more between rows than the differences being
// measured): kinema's variants in `interleaved`, the peer beside one thread in `peer`. Both
// job systems want the process's oneTBB worker threads (one, on two hardware threads), so
// taking turns in one row measured each starved by the other: at 16k float with 8 ms gaps
// the default read 1.02x one thread and parallel_for 0.85x, where each alone reads more.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <memory>
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

// The default job system's spinning so far (seconds of one core).
double spin_seconds() { return dynamic_cast<TbbJobSystem&>(default_job_system()).spin_seconds(); }

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

using Variants = std::vector<std::pair<Variant, const char*>>;
const Variants kVariants = {{Variant::one_thread, "threads:1"},
                            {Variant::measured, "default"},
                            {Variant::prepared, "prepared"},
                            {Variant::two_threads, "threads:2"},
                            {Variant::parallel_for, "parallel_for"}};
// With gaps: the rows' variants, one thread first (what the others are paired against).
const Variants kKinemaVariants(kVariants.begin(), kVariants.end() - 1);
const Variants kPeerVariants = {kVariants.front(), kVariants.back()};

// One variant's stepper and bodies, and the time of each frame's step it played.
template <class T>
struct Player {
  Player(Variant v, std::size_t n)
      : variant(v), bodies(cached_particles<T>(n)), stepper(make_forces<T>(bench_scene(n)), rk4, options_for(v)) {}

  // Sleeps `gap` (the rest of the frame), then times the step (prepare too, where used).
  double frame(std::chrono::microseconds gap) {
    if (gap.count() > 0) std::this_thread::sleep_for(gap);
    const auto begin = std::chrono::steady_clock::now();
    if (variant == Variant::prepared) stepper.prepare();
    stepper.step(bodies, T(kDt));
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    if (++frames % kRestoreEvery == 0) restore(bodies, cached_particles<T>(bodies.size()));
    return s;
  }

  Variant variant;
  ParticleSet<T> bodies;
  Stepper<T> stepper;
  std::int64_t frames = 0;
  std::vector<double> seconds;
};

// Back to back: one variant per row, each step right after the last.
template <class T>
void back_to_back(benchmark::State& state, Variant variant) {
  const auto n = std::size_t(state.range(0));
  Player<T> player(variant, n);
  for (int k = 0; k < kWarmFrames; ++k) player.frame({});
  player.seconds.reserve(std::size_t(std::min<benchmark::IterationCount>(state.max_iterations, 1 << 22)));
  for (auto _ : state) {
    player.seconds.push_back(player.frame({}));
    state.SetIterationTime(player.seconds.back());
  }
  require_finite(state, player.bodies);
  report_body_steps(state, double(n), particle_step_bytes<T>());
  state.counters["workers"] = player.stepper.chosen_workers();
  // The typical step: a pre-empted one moves the mean (the time columns), not this.
  state.counters["median_ns_per_body_step"] = median(player.seconds) * 1e9 / double(n);
}

// With idle gaps: every variant plays a run of kRun frames per iteration, in turn, so that
// all of them meet the same moments of a shared machine, and each meets a frame loop's
// steady cadence (what the default job system's workers anticipate) for most of its frames;
// the counters are each variant's median and mean step (ns per body-step) over the run's
// frames, every frame of a run counted.
constexpr int kRun = 8;

template <class T>
void interleaved(benchmark::State& state, int gap_us, const Variants& variants) {
  const auto n = std::size_t(state.range(0));
  const auto gap = std::chrono::microseconds(gap_us);
  std::vector<std::unique_ptr<Player<T>>> players;
  for (const auto& [variant, label] : variants) players.push_back(std::make_unique<Player<T>>(variant, n));
  for (int k = 0; k < kWarmFrames; ++k) {
    for (auto& p : players) p->frame(gap);
  }
  const double spun_before = spin_seconds();
  for (auto _ : state) {
    double round = 0;
    for (auto& p : players) {
      for (int k = 0; k < kRun; ++k) {
        p->seconds.push_back(p->frame(gap));
        round += p->seconds.back();
      }
    }
    state.SetIterationTime(round);
  }
  const std::vector<double>& alone = players[0]->seconds;  // threads:1
  for (std::size_t v = 0; v < players.size(); ++v) {
    const std::vector<double>& s = players[v]->seconds;
    double sum = 0;
    std::vector<double> speed;  // against one thread, round by round: a paired figure
    for (std::size_t k = 0; k < s.size(); ++k) sum += s[k], speed.push_back(alone[k] / s[k]);
    const std::string label = variants[v].second;
    state.counters["median:" + label] = median(s) * 1e9 / double(n);
    state.counters["mean:" + label] = s.empty() ? 0 : sum / double(s.size()) * 1e9 / double(n);
    state.counters["speed:" + label] = median(speed);
    require_finite(state, players[v]->bodies);
  }
  if (players[1]->variant != Variant::measured) return;  // the peer's row
  state.counters["workers"] = players[1]->stepper.chosen_workers();
  // What keeping the workers ready cost: their spinning, per frame of the whole row (every
  // variant's frames: the spinning goes on through the others' gaps).
  const double frames = double(players.size() * kRun) * double(state.iterations());
  state.counters["spin_us_per_frame"] = (spin_seconds() - spun_before) * 1e6 / frames;
}

void register_all() {
  const std::int64_t sizes[] = {1024, 4096, 16384, 65536, 100000, 1 << 20};
  for (const auto& [variant, label] : kVariants) {
    const std::string suffix = std::string("/gap_us:0/") + label;
    for (auto* b : {benchmark::RegisterBenchmark(("frame_loop/float" + suffix).c_str(), back_to_back<float>, variant),
                    benchmark::RegisterBenchmark(("frame_loop/double" + suffix).c_str(), back_to_back<double>, variant)}) {
      for (std::int64_t n : sizes) b->Arg(n);
      b->UseManualTime()->Unit(benchmark::kMicrosecond);
    }
  }
  // Rounds are counted, not timed to a minimum: the gaps are most of the time.
  for (const auto& [gap_us, rounds] : {std::pair{1000, 30}, std::pair{8000, 12}}) {
    for (const auto& [row, variants] : {std::pair{"/interleaved", &kKinemaVariants}, std::pair{"/peer", &kPeerVariants}}) {
      const std::string suffix = "/gap_us:" + std::to_string(gap_us) + row;
      for (auto* b : {benchmark::RegisterBenchmark(("frame_loop/float" + suffix).c_str(), interleaved<float>, gap_us,
                                                   *variants),
                      benchmark::RegisterBenchmark(("frame_loop/double" + suffix).c_str(), interleaved<double>, gap_us,
                                                   *variants)}) {
        for (std::int64_t n : sizes) b->Arg(n);
        b->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(rounds);
      }
    }
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
