// Benchmarks of the machine's limits: streaming bandwidth at the kernels' state sizes, the
// FMA peak, and the 2-thread scaling of pure FMA work (are the two vCPUs real cores?).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bench_scene.hpp"
#include "limits.hpp"

namespace kinema::bench {

const LimitKernels& best_limits() {
  static const LimitKernels k = isa_available(Isa::avx512) ? limits_avx512()
                                : isa_available(Isa::avx2) ? limits_avx2()
                                                           : limits_sse2();
  return k;
}

namespace {

struct StreamArrays {
  AlignedArray<float> x, v;
};

// Two float arrays holding as many bytes as `bodies` float particles' state (7 arrays),
// made once per size and shared by the benchmark's threads.
StreamArrays& stream_arrays(std::size_t bodies) {
  static std::mutex mutex;
  static std::map<std::size_t, StreamArrays> arrays;
  std::lock_guard lock(mutex);
  auto [it, fresh] = arrays.try_emplace(bodies);
  if (fresh) {
    const std::size_t total = padded_count<float>(bodies * 7 / 2 + 16);
    it->second.x = AlignedArray<float>(total);
    it->second.v = AlignedArray<float>(total);
    for (std::size_t i = 0; i < total; ++i) it->second.v[i] = 1e-3f;
  }
  return it->second;
}

// x += h v; each benchmark thread streams its own share.
void stream_in_place(benchmark::State& state) {
  StreamArrays& a = stream_arrays(std::size_t(state.range(0)));
  AlignedArray<float>& x = a.x;
  const AlignedArray<float>& v = a.v;
  const std::size_t total = x.size();
  const std::size_t per_thread = total / std::size_t(state.threads()) / 16 * 16;
  const std::size_t begin = per_thread * std::size_t(state.thread_index());
  for (auto _ : state) {
    best_limits().stream(x.data() + begin, v.data() + begin, per_thread, 1e-3f);
    benchmark::ClobberMemory();
  }
  const double bytes = 3.0 * sizeof(float) * double(per_thread) * double(state.iterations());
  state.counters["GB_per_s"] = benchmark::Counter(bytes * 1e-9, benchmark::Counter::kIsRate);
  state.SetLabel(best_limits().isa);
}

template <class T>
struct StateArraysOf {
  AlignedArray<T> a[7];  // px py pz vx vy vz w
};

// A particle set's state arrays at each size, made once and shared by the benchmark's threads.
template <class T>
StateArraysOf<T>& state_arrays(std::size_t bodies) {
  static std::mutex mutex;
  static std::map<std::size_t, StateArraysOf<T>> arrays;
  std::lock_guard lock(mutex);
  auto [it, fresh] = arrays.try_emplace(bodies);
  if (fresh) {
    for (auto& array : it->second.a) {
      array = AlignedArray<T>(padded_count<T>(bodies));
      for (std::size_t i = 0; i < array.size(); ++i) array[i] = T(1e-3);
    }
  }
  return it->second;
}

// The state's own traffic (7 arrays read, 6 written): the memory limit of a fused step at
// this size and thread count. Each benchmark thread streams its own share of the bodies.
template <class T>
void state_stream(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  const auto ahead = std::size_t(state.range(1));
  StateArraysOf<T>& s = state_arrays<T>(n);
  T* const p[3] = {s.a[0].data(), s.a[1].data(), s.a[2].data()};
  T* const v[3] = {s.a[3].data(), s.a[4].data(), s.a[5].data()};
  const std::size_t share = padded_count<T>(n) / std::size_t(state.threads()) / 16 * 16;
  const std::size_t begin = share * std::size_t(state.thread_index());
  for (auto _ : state) {
    if constexpr (sizeof(T) == 4) {
      best_limits().state_stream_float(p, v, s.a[6].data(), begin, begin + share, T(1e-9), ahead);
    } else {
      best_limits().state_stream_double(p, v, s.a[6].data(), begin, begin + share, T(1e-9), ahead);
    }
    benchmark::ClobberMemory();
  }
  const double bytes = 13.0 * sizeof(T) * double(share) * double(state.iterations());
  state.counters["GB_per_s"] = benchmark::Counter(bytes * 1e-9, benchmark::Counter::kIsRate);
  state.SetLabel(best_limits().isa);
}

template <class T>
void fma_peak(benchmark::State& state) {
  double flops = 0, total = 0;
  for (auto _ : state) {
    if constexpr (sizeof(T) == 4) {
      benchmark::DoNotOptimize(best_limits().peak_float(1 << 16, &flops));
    } else {
      benchmark::DoNotOptimize(best_limits().peak_double(1 << 16, &flops));
    }
    total += flops;
  }
  state.counters["GFLOP_per_s"] = benchmark::Counter(total * 1e-9, benchmark::Counter::kIsRate);
  state.SetLabel(best_limits().isa);
}

// A limit is what the machine can do: the best repetition (others lost time to a neighbour).
double best(const std::vector<double>& v) { return v.empty() ? 0 : *std::max_element(v.begin(), v.end()); }

void register_all() {
  // x += h v over the 38.7 MB a 512 x 512 cloth's spring kernel moves (1382400 bodies' state).
  benchmark::RegisterBenchmark("limit/stream", stream_in_place)
      ->Arg(1382400)->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond)->ComputeStatistics("max", best);
  // And over the 17.0 MB one conjugate-gradient iteration of the 256 x 256 cloth works in
  // (bench/implicit.cpp: 260 bytes a body, 608549 bodies' state).
  benchmark::RegisterBenchmark("limit/stream", stream_in_place)
      ->Arg(608549)->Threads(1)->UseRealTime()->Unit(benchmark::kMicrosecond)->ComputeStatistics("max", best);
  for (std::int64_t n : {1 << 10, 1 << 12, 1 << 14, 1 << 16, 100000, 1 << 20, 1 << 22}) {
    for (std::int64_t ahead : {0, 1024, 4096}) {
      benchmark::RegisterBenchmark("limit/state_stream/float", state_stream<float>)
          ->Args({n, ahead})->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond)->ComputeStatistics("max", best);
      benchmark::RegisterBenchmark("limit/state_stream/double", state_stream<double>)
          ->Args({n, ahead})->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond)->ComputeStatistics("max", best);
    }
  }
  benchmark::RegisterBenchmark("limit/fma_peak/float", fma_peak<float>)
      ->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond)->ComputeStatistics("max", best);
  benchmark::RegisterBenchmark("limit/fma_peak/double", fma_peak<double>)
      ->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond)->ComputeStatistics("max", best);
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
