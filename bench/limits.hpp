#pragma once
// The machine's own limits, measured in the same run as the kernels: in-place streaming
// bandwidth (x += h v) and the FMA peak. Each has a version per instruction set, compiled in
// its own unit; the best available one runs.

#include <cstddef>

namespace kinema::bench {

// x[i] += h * v[i] for i in [0, n); x and v 64-byte aligned, n a multiple of 16.
using StreamFn = void (*)(float* x, const float* v, std::size_t n, float h);
// `rounds` rounds of dependent FMAs over independent accumulators; returns a checksum and
// the FLOPs done through out_flops.
using PeakFloatFn = float (*)(long rounds, double* out_flops);
using PeakDoubleFn = double (*)(long rounds, double* out_flops);

// The particle state's own traffic, bodies [begin, end): 7 arrays read, 6 written in place
// (p += h v, then v += h w p per axis), as a step of the fused kernels moves them, with
// almost no arithmetic, each array asked for `ahead` bytes ahead (0: not at all). All
// pointers 64-byte aligned, begin and end multiples of 16.
template <class T>
using StateStreamFn = void (*)(T* const p[3], T* const v[3], const T* w, std::size_t begin,
                               std::size_t end, T h, std::size_t ahead);

struct LimitKernels {
  const char* isa;
  StreamFn stream;
  StateStreamFn<float> state_stream_float;
  StateStreamFn<double> state_stream_double;
  PeakFloatFn peak_float;
  PeakDoubleFn peak_double;
};

LimitKernels limits_avx512();
LimitKernels limits_avx2();
LimitKernels limits_sse2();

// The versions for the best instruction set this CPU has.
const LimitKernels& best_limits();

}  // namespace kinema::bench
