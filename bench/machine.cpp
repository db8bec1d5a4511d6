// Benchmarks of the machine's limits: streaming bandwidth at the kernels' state sizes, the
// FMA peak, and the 2-thread scaling of pure FMA work (are the two vCPUs real cores?).
#include <benchmark/benchmark.h>

#include <map>
#include <mutex>
#include <string>
#include <thread>

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

void register_all() {
  // 1382400 bodies' state is the 38.7 MB a 512 x 512 cloth's spring kernel moves.
  for (std::int64_t n : {1 << 10, 1 << 14, 100000, 1 << 20, 1382400, 1 << 22}) {
    benchmark::RegisterBenchmark("limit/stream", stream_in_place)
        ->Arg(n)->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
  }
  benchmark::RegisterBenchmark("limit/fma_peak/float", fma_peak<float>)
      ->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("limit/fma_peak/double", fma_peak<double>)
      ->Threads(1)->Threads(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
