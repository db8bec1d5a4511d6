// kinema's particle paths: fused step by step (what a frame loop does), the same kernel with
// its memory traffic removed (advance(): each cache-sized block takes every step in turn),
// and the staged path, per method, precision, size, thread count and instruction set.
#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "bench_scene.hpp"

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

std::string name(const char* kind, const Case& c, const char* precision) {
  return std::string(kind) + "/" + std::string(c.method->name) + "/" + precision + "/" +
         std::string(isa_name(c.isa)) + "/threads:" + std::to_string(c.threads);
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
