// kinema's particle paths: fused step by step (what a frame loop does), the same kernel with
// its memory traffic removed (advance(): each cache-sized block takes every step in turn),
// and the staged path, per method, precision, size, thread count and instruction set; and
// the 2-thread scaling measured in pairs, each pair checked against pure FMA work.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "bench_scene.hpp"
#include "limits.hpp"

namespace kinema::bench {
namespace {

constexpr std::int64_t kCeilingSteps = 64;

struct Case {
  const Method* method;
  Isa isa;
  unsigned threads;
  bool staged;
  bool relaxed = false;
};

// The stepper a case describes, with the job system it runs on.
template <class T>
struct CaseStepper {
  TbbJobSystem jobs;
  SerialJobSystem serial;
  Stepper<T> stepper;

  CaseStepper(const Case& c, std::size_t n)
      : jobs(c.threads), stepper(make_forces<T>(bench_scene(n)), *c.method, options(c)) {}

  StepperOptions options(const Case& c) {
    StepperOptions o;
    o.isa = c.isa;
    o.jobs = c.threads == 1 ? static_cast<JobSystem*>(&serial) : &jobs;
    o.force_staged = c.staged;
    o.workers = WorkerChoice::all;  // n threads, not the measured choice (frame_loop times that)
    o.relaxed_fma = c.relaxed;
    return o;
  }
};

// Steps the case's bodies `per_iteration` steps per benchmark iteration: 1 through step()
// (what a frame loop does), more through advance() (the temporally blocked ceiling).
template <class T>
void run_steps(benchmark::State& state, const Case& c, std::int64_t per_iteration) {
  const auto n = std::size_t(state.range(0));
  const ParticleSet<T>& initial = cached_particles<T>(n);
  ParticleSet<T> bodies = initial;
  CaseStepper<T> run(c, n);
  auto steps = [&] {
    if (per_iteration == 1) {
      run.stepper.step(bodies, T(kDt));
    } else {
      run.stepper.advance(bodies, T(kDt), std::uint64_t(per_iteration));
    }
  };
  steps();  // warm: first-touch, scratch
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % (kRestoreEvery / per_iteration) == 0) restore(bodies, initial);
    steps();
    benchmark::ClobberMemory();
  }
  benchmark::DoNotOptimize(bodies.px());
  require_finite(state, bodies);
  report_body_steps(state, double(n) * double(per_iteration), particle_step_bytes<T>());
}

template <class T>
void step_by_step(benchmark::State& state, Case c) {
  run_steps<T>(state, c, 1);
}

template <class T>
void temporally_blocked(benchmark::State& state, Case c) {
  run_steps<T>(state, c, kCeilingSteps);
}

// Two items of pure FMA work through a job system: how much faster two workers run them than
// one, right now.
struct FmaProbe {
  long rounds;
  float sink[2] = {};
};

void fma_items(std::size_t begin, std::size_t end, unsigned, void* context) {
  auto& probe = *static_cast<FmaProbe*>(context);
  double flops = 0;
  for (std::size_t i = begin; i < end; ++i) probe.sink[i] = best_limits().peak_float(probe.rounds, &flops);
}

template <class Run>
double seconds(Run&& run) {
  const auto start = std::chrono::steady_clock::now();
  run();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Items of about 100 us; the 2-thread run follows a shorter one, so that a worker that fell
// asleep during the 1-thread run is awake (waking one takes tens of microseconds here).
double fma_scaling(JobSystem& two) {
  FmaProbe probe{1 << 15};
  FmaProbe wake{1 << 14};
  SerialJobSystem one;
  const double t1 = seconds([&] { one.wait(one.enqueue(&fma_items, 2, 1, &probe)); });
  two.wait(two.enqueue(&fma_items, 2, 1, &wake));
  const double t2 = seconds([&] { two.wait(two.enqueue(&fma_items, 2, 1, &probe)); });
  benchmark::DoNotOptimize(probe.sink);
  benchmark::DoNotOptimize(wake.sink);
  return t1 / t2;
}

// Each iteration is one round: an FMA probe, a few steps on 1 thread, the same steps on 2,
// another probe. Separate 1- and 2-thread runs are minutes apart and a shared host drifts
// in between; a pair is seconds of the same conditions. Pairs count only when both probes
// scaled 1.8x (two real cores at that moment). Reports the median ratio of those pairs, and
// of all pairs.
template <class T>
void paired_scaling(benchmark::State& state, Case c) {
  const auto n = std::size_t(state.range(0));
  const int steps = std::max(1, int(2'000'000 / n));  // 2-4 ms on one thread
  ParticleSet<T> bodies[2] = {cached_particles<T>(n), cached_particles<T>(n)};
  c.threads = 1;
  CaseStepper<T> one(c, n);
  c.threads = 2;
  CaseStepper<T> two(c, n);
  CaseStepper<T>* runs[2] = {&one, &two};
  std::vector<double> fma, pairs, all_pairs;
  for (auto _ : state) {
    double t[2];
    const double before = fma_scaling(two.jobs);
    for (int r = 0; r < 2; ++r) {
      restore(bodies[r], cached_particles<T>(n));
      runs[r]->stepper.step(bodies[r], T(kDt));  // warm
      t[r] = seconds([&] {
        for (int k = 0; k < steps; ++k) runs[r]->stepper.step(bodies[r], T(kDt));
      });
    }
    const double after = fma_scaling(two.jobs);
    fma.push_back(std::min(before, after));
    all_pairs.push_back(t[0] / t[1]);
    if (fma.back() >= 1.8) pairs.push_back(all_pairs.back());
  }
  require_finite(state, bodies[1]);
  // 0 when no pair was kept, so that the median over repetitions counts those too.
  state.counters["scaling"] = median(pairs);
  state.counters["scaling_all_pairs"] = median(all_pairs);
  state.counters["fma_scaling"] = median(fma);
  state.counters["pairs_kept"] = double(pairs.size());
  state.counters["pairs"] = double(fma.size());
}

std::string name(const char* kind, const Case& c, const char* precision) {
  return std::string(kind) + "/" + std::string(c.method->name) + "/" + precision + "/" +
         std::string(isa_name(c.isa)) + "/threads:" + std::to_string(c.threads);
}

void register_paired_scaling(Isa isa) {
  const Case paired{&rk4, isa, 2, false};
  const std::string suffix = std::string("/") + std::string(isa_name(isa));
  for (auto* b : {benchmark::RegisterBenchmark(("scaling/rk4/float" + suffix).c_str(),
                                               paired_scaling<float>, paired),
                  benchmark::RegisterBenchmark(("scaling/rk4/double" + suffix).c_str(),
                                               paired_scaling<double>, paired)}) {
    b->Arg(100000)->Unit(benchmark::kMillisecond);
  }
}

void register_all() {
  const std::int64_t sizes[] = {1 << 10, 1 << 14, 100000, 1 << 20, 1 << 22};
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    for (const Method* m : builtin_methods) {
      for (unsigned threads : {1u, 2u}) {
        const Case c{m, isa, threads, false};
        auto* f = benchmark::RegisterBenchmark(name("fused", c, "float").c_str(),
                                               step_by_step<float>, c);
        auto* d = benchmark::RegisterBenchmark(name("fused", c, "double").c_str(),
                                               step_by_step<double>, c);
        for (auto* b : {f, d}) {
          for (std::int64_t n : sizes) b->Arg(n);
          b->UseRealTime()->Unit(benchmark::kMicrosecond);
        }
        // The ceiling does not depend on N (the state never leaves cache): one size.
        for (auto* b : {benchmark::RegisterBenchmark(name("ceiling", c, "float").c_str(),
                                                     temporally_blocked<float>, c),
                        benchmark::RegisterBenchmark(name("ceiling", c, "double").c_str(),
                                                     temporally_blocked<double>, c)}) {
          b->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
        }
        const Case s{m, isa, threads, true};
        auto* st = benchmark::RegisterBenchmark(name("staged", s, "float").c_str(),
                                                step_by_step<float>, s);
        st->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
      }
    }
    if (isa == best_isa()) register_paired_scaling(isa);
    if (isa == Isa::scalar || isa == Isa::sse2) {
      // What exact fused multiply-adds cost where there is no FMA unit.
      const Case r{&rk4, isa, 1, false, true};
      for (auto* b : {benchmark::RegisterBenchmark(name("relaxed", r, "float").c_str(),
                                                   step_by_step<float>, r),
                      benchmark::RegisterBenchmark(name("relaxed", r, "double").c_str(),
                                                   step_by_step<double>, r)}) {
        b->Arg(100000)->UseRealTime()->Unit(benchmark::kMicrosecond);
      }
    }
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
