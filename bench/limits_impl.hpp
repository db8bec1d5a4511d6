#pragma once
// Written once over xsimd batches; FMA through the instruction itself (see src/kernels).
#include <xsimd/xsimd.hpp>

#include "limits.hpp"

namespace kinema::bench::LIMITS_NS {

template <class B>
inline B fma_op(const B& a, const B& b, const B& c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_ps(a, b, c);
#else
  return xsimd::fma(a, b, c);
#endif
}

template <class B>
inline B fma_op_d(const B& a, const B& b, const B& c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_pd(a, b, c);
#else
  return xsimd::fma(a, b, c);
#endif
}

template <class A>
void stream(float* x, const float* v, std::size_t n, float h) {
  using B = xsimd::batch<float, A>;
  const B hb(h);
  for (std::size_t i = 0; i < n; i += B::size) {
    if (i % 16 == 0) {  // once per cache line, 1 KiB ahead, as the kernels do
      __builtin_prefetch(x + i + 256, 1);
      __builtin_prefetch(v + i + 256, 0);
    }
    fma_op(hb, B::load_aligned(v + i), B::load_aligned(x + i)).store_aligned(x + i);
  }
}

// 12 independent chains hide the FMA latency (4 cycles) on two pipes.
template <class T, class A, class Op>
T peak(long rounds, double* out_flops, Op op) {
  using B = xsimd::batch<T, A>;
  constexpr int kChains = 12;
  B acc[kChains];
  for (int c = 0; c < kChains; ++c) acc[c] = B(T(1) + T(c) * T(1e-3));
  const B a(T(0.999999)), b(T(1e-7));
  for (long r = 0; r < rounds; ++r) {
    for (int c = 0; c < kChains; ++c) acc[c] = op(acc[c], a, b);
  }
  B sum = acc[0];
  for (int c = 1; c < kChains; ++c) sum += acc[c];
  *out_flops = 2.0 * double(B::size) * kChains * double(rounds);
  // xsimd 8.1's hadd on avx512f needs AVX512DQ: sum the lanes by hand.
  alignas(64) T lanes[B::size];
  sum.store_aligned(lanes);
  T total = 0;
  for (T x : lanes) total += x;
  return total;
}

template <class A>
LimitKernels make(const char* name) {
  return {name, &stream<A>,
          [](long rounds, double* flops) {
            return peak<float, A>(rounds, flops, [](auto a, auto b, auto c) { return fma_op(a, b, c); });
          },
          [](long rounds, double* flops) {
            return peak<double, A>(rounds, flops, [](auto a, auto b, auto c) { return fma_op_d(a, b, c); });
          }};
}

}  // namespace kinema::bench::LIMITS_NS
