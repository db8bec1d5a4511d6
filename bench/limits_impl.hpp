#pragma once
// Written once over xsimd batches; FMA through the instruction itself (see src/kernels).
#include <type_traits>

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

template <class B>
inline B fma_any(const B& a, const B& b, const B& c) {
  if constexpr (std::is_same_v<typename B::value_type, float>) {
    return fma_op(a, b, c);
  } else {
    return fma_op_d(a, b, c);
  }
}

template <class T, class A>
void state_stream(T* const p_in[3], T* const v_in[3], const T* w, std::size_t begin, std::size_t end, T h,
                  std::size_t ahead) {
  using B = xsimd::batch<T, A>;
  // Copies: stores cannot alias them, so the pointers stay in registers (as in the kernels).
  T* const p[3] = {p_in[0], p_in[1], p_in[2]};
  T* const v[3] = {v_in[0], v_in[1], v_in[2]};
  constexpr std::size_t kLine = 64 / sizeof(T);
  const std::size_t kAhead = ahead / sizeof(T);
  const B hb(h);
  for (std::size_t i = begin; i < end; i += B::size) {
    if (kAhead > 0 && i % kLine == 0) {
      for (int d = 0; d < 3; ++d) {
        __builtin_prefetch(p[d] + i + kAhead, 1);
        __builtin_prefetch(v[d] + i + kAhead, 1);
      }
      __builtin_prefetch(w + i + kAhead, 0);
    }
    const B hw = hb * B::load_aligned(w + i);
    for (int d = 0; d < 3; ++d) {
      const B x = fma_any(hb, B::load_aligned(v[d] + i), B::load_aligned(p[d] + i));
      x.store_aligned(p[d] + i);
      fma_any(hw, x, B::load_aligned(v[d] + i)).store_aligned(v[d] + i);
    }
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
  return {name, &stream<A>, &state_stream<float, A>, &state_stream<double, A>,
          [](long rounds, double* flops) {
            return peak<float, A>(rounds, flops, [](auto a, auto b, auto c) { return fma_op(a, b, c); });
          },
          [](long rounds, double* flops) {
            return peak<double, A>(rounds, flops, [](auto a, auto b, auto c) { return fma_op_d(a, b, c); });
          }};
}

}  // namespace kinema::bench::LIMITS_NS
