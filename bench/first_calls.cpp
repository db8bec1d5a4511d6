// A program's first calls, as an engine meets them: a fresh process, default options or one
// thread, one rk4 step after another over the benchmark scene's bodies. Prints the mean step
// over the calls after the warm-up and the first call after which the stepper favours
// workers (-1: never, or one thread). tools/bench --first-calls runs it in fresh processes, its
// four kinds in turn:
//   kinema_first_calls [--threads N] [--workers measured|all] [--bodies N] [--calls N]
//                      [--warmup N] [--gap-us N] [--trace]
//   kinema_first_calls --jobs pair [--bodies N] [--calls N] [--warmup N] [--gap-us N] [--trace]
// --threads 0 (the default) is the default job system, 1 the calling thread alone;
// --workers all hands every call to all of the job system's workers; --jobs pair every call
// to SpinningPair (below); --gap-us sleeps that long before each call, as a frame loop's idle
// time does (0, the default: back to back). Exit code 2 for bad options, 1 for an error while
// stepping.
#include <atomic>
#include <chrono>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <thread>

#include <immintrin.h>

#include "bench_scene.hpp"

namespace {

// The least a second core can cost a call: one helper thread that spins for the next job,
// each call cut into two fixed halves, the caller running the first. No stealing, no
// sleeping, three cache lines shared per call (the job, its ticket, the helper's done count).
// For one host thread that never calls it from inside a task, and for calls that want every
// worker (WorkerChoice::all: min_range 1, so any split is allowed).
class SpinningPair final : public kinema::JobSystem {
 public:
  SpinningPair() : helper_([this] { serve(); }) {}
  ~SpinningPair() override {
    quit_.store(true, std::memory_order_release);
    helper_.join();
  }
  unsigned worker_count() const override { return 2; }
  kinema::JobHandle enqueue(kinema::RangeTask task, std::size_t items, std::size_t, void* context) override {
    const std::size_t half = items / 2;
    job_ = {task, context, half, items};
    const std::uint64_t ticket = posted_.load(std::memory_order_relaxed) + 1;
    posted_.store(ticket, std::memory_order_release);
    if (half > 0) task(0, half, 0, context);
    while (done_.load(std::memory_order_acquire) != ticket) _mm_pause();
    return nullptr;
  }
  void wait(kinema::JobHandle) override {}

 private:
  struct Job {
    kinema::RangeTask task = nullptr;
    void* context = nullptr;
    std::size_t begin = 0, end = 0;
  };
  void serve() {
    std::uint64_t seen = 0;
    while (!quit_.load(std::memory_order_acquire)) {
      const std::uint64_t ticket = posted_.load(std::memory_order_acquire);
      if (ticket == seen) {
        _mm_pause();
        continue;
      }
      seen = ticket;
      if (job_.begin < job_.end) job_.task(job_.begin, job_.end, 1, job_.context);
      done_.store(ticket, std::memory_order_release);
    }
  }
  alignas(64) Job job_;
  alignas(64) std::atomic<std::uint64_t> posted_{0};
  alignas(64) std::atomic<std::uint64_t> done_{0};
  alignas(64) std::atomic<bool> quit_{false};
  std::thread helper_;
};

struct Options {
  unsigned threads = 0;
  bool all_workers = false;
  bool spinning_pair = false;  // --jobs pair: SpinningPair instead of the default job system
  bool trace = false;  // each call's time and worker choice on stderr
  std::size_t bodies = 16384;
  int calls = 420;
  int warmup = 20;
  long gap_us = 0;  // sleep before each call (a frame loop's idle time)
};

[[noreturn]] void refuse(const std::string& why) {
  std::fprintf(stderr, "kinema_first_calls: %s (see the head of bench/first_calls.cpp)\n", why.c_str());
  std::exit(2);
}

// A whole number in [low, high], all of `text`.
long long parse_count(const char* flag, const char* text, long long low, long long high) {
  char* end = nullptr;
  errno = 0;
  const long long value = std::strtoll(text, &end, 10);
  if (end == text || *end != '\0' || errno == ERANGE || value < low || value > high) {
    refuse(std::string(flag) + " needs a whole number in [" + std::to_string(low) + ", " + std::to_string(high) +
           "], not '" + text + "'");
  }
  return value;
}

bool one_of(const char* value, const char* a, const char* b) {
  return std::strcmp(value, a) == 0 || (b != nullptr && std::strcmp(value, b) == 0);
}

Options parse(int argc, char** argv) {
  Options o;
  bool threads_given = false;
  for (int a = 1; a < argc; ++a) {
    const std::string flag = argv[a];
    if (flag == "--trace") {
      o.trace = true;
      continue;
    }
    if (a + 1 == argc) refuse("'" + flag + "' needs a value");
    const char* value = argv[++a];
    constexpr long long kMaxCount = 1 << 30;
    if (flag == "--threads") {
      o.threads = unsigned(parse_count("--threads", value, 0, 1024));
      threads_given = true;
    } else if (flag == "--workers") {
      if (!one_of(value, "all", "measured")) refuse("--workers takes all or measured, not '" + std::string(value) + "'");
      o.all_workers = one_of(value, "all", nullptr);
    } else if (flag == "--jobs") {
      if (!one_of(value, "pair", nullptr)) refuse("--jobs takes pair, not '" + std::string(value) + "'");
      o.spinning_pair = true;
    } else if (flag == "--bodies") {
      o.bodies = std::size_t(parse_count("--bodies", value, 1, kMaxCount));
    } else if (flag == "--calls") {
      o.calls = int(parse_count("--calls", value, 2, kMaxCount));
    } else if (flag == "--gap-us") {
      o.gap_us = long(parse_count("--gap-us", value, 0, 1000000));
    } else if (flag == "--warmup") {
      o.warmup = int(parse_count("--warmup", value, 0, kMaxCount));
    } else {
      refuse("unknown option '" + flag + "'");
    }
  }
  if (o.warmup >= o.calls) refuse("--warmup must be below --calls");
  if (o.spinning_pair && (threads_given || o.all_workers)) refuse("--jobs pair takes neither --threads nor --workers");
  return o;
}

// Steps as the options say and prints the one line tools/bench reads.
void step_calls(const Options& o) {
  using namespace kinema;
  using Clock = std::chrono::steady_clock;
  const Scene scene = bench::bench_scene(o.bodies);
  ParticleSet<float> bodies = make_particles<float>(scene);
  StepperOptions options = o.threads == 1 ? on_calling_thread() : StepperOptions{};
  options.threads = o.threads == 1 ? 0 : o.threads;
  if (o.all_workers) options.workers = WorkerChoice::all;
  std::unique_ptr<SpinningPair> pair;
  if (o.spinning_pair) {
    pair = std::make_unique<SpinningPair>();
    options.jobs = pair.get();
    options.workers = WorkerChoice::all;
  }
  Stepper<float> stepper(make_forces<float>(scene), rk4, options);
  int first_with_workers = -1;
  double timed = 0;
  for (int call = 0; call < o.calls; ++call) {
    if (o.gap_us > 0) std::this_thread::sleep_for(std::chrono::microseconds(o.gap_us));
    const auto start = Clock::now();
    stepper.step(bodies, float(bench::kDt));
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    if (call >= o.warmup) timed += seconds;
    if (o.trace) std::fprintf(stderr, "call %d us %.3f favoured %u\n", call, 1e6 * seconds, stepper.chosen_workers());
    if (o.threads != 1 && first_with_workers < 0 && stepper.chosen_workers() > 0) first_with_workers = call;
  }
  std::printf("threads %u jobs %s bodies %zu calls %d mean_us %.3f first_call_favouring_workers %d\n", o.threads,
              o.spinning_pair ? "pair" : "default", o.bodies, o.calls, 1e6 * timed / (o.calls - o.warmup),
              first_with_workers);
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  try {
    step_calls(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kinema_first_calls: %s\n", e.what());
    return 1;
  }
  return 0;
}
