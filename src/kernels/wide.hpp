#pragma once
// The handful of operations the kernels use, for a scalar T and for xsimd batches.
// Included by each per-ISA translation unit inside its own namespace (KINEMA_ISA_NS), so
// inline functions compiled with different flags never merge at link time.
//
// mul_add(a, b, c) is a*b + c with one rounding on every path: the FMA instructions on AVX2
// and AVX-512, std::fma on the scalar path, and on SSE2 an exact emulation for float
// (exact_fma.hpp) and std::fma per lane for double. With -ffp-contract=off the compiler never fuses anything else,
// so every path computes the same bits.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include <xsimd/xsimd.hpp>

#include "kernels/exact_fma.hpp"

// Kernel helpers must melt into the kernel loops: GCC's heuristics stop inlining the
// larger ones once several kernels share them, and a helper left as a call costs the kernel
// most of its speed.
#ifndef KINEMA_INLINE
#define KINEMA_INLINE inline __attribute__((always_inline))
#endif

namespace kinema::kernels::KINEMA_ISA_NS {

template <class V>
struct Lane {
  using value_type = V;
  static constexpr std::size_t width = 1;
};
template <class T, class A>
struct Lane<xsimd::batch<T, A>> {
  using value_type = T;
  static constexpr std::size_t width = xsimd::batch<T, A>::size;
};

template <class V>
using value_t = typename Lane<V>::value_type;

template <class V>
KINEMA_INLINE V load(const value_t<V>* p) {
  if constexpr (std::is_floating_point_v<V>) {
    return *p;
  } else {
    return V::load_aligned(p);
  }
}

template <class V>
KINEMA_INLINE void store(value_t<V>* p, const V& v) {
  if constexpr (std::is_floating_point_v<V>) {
    *p = v;
  } else {
    v.store_aligned(p);
  }
}

template <class V>
KINEMA_INLINE V load_unaligned(const value_t<V>* p) {
  if constexpr (std::is_floating_point_v<V>) {
    return *p;
  } else {
    return V::load_unaligned(p);
  }
}

// Lane l takes base[index[l]]: the gather instructions on AVX2 and AVX-512, one load per
// lane elsewhere.
template <class V>
KINEMA_INLINE V gather(const value_t<V>* base, const std::int32_t* index) {
  using T = value_t<V>;
  if constexpr (std::is_floating_point_v<V>) {
    return base[*index];
#if defined(__AVX512F__)
  } else if constexpr (std::is_same_v<V, xsimd::batch<float, xsimd::avx512f>>) {
    return _mm512_i32gather_ps(_mm512_loadu_si512(index), base, 4);
  } else if constexpr (std::is_same_v<V, xsimd::batch<double, xsimd::avx512f>>) {
    return _mm512_i32gather_pd(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(index)), base, 8);
#endif
#if defined(__AVX2__)
  } else if constexpr (std::is_same_v<V, xsimd::batch<float, xsimd::fma3<xsimd::avx2>>>) {
    return _mm256_i32gather_ps(base, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(index)), 4);
  } else if constexpr (std::is_same_v<V, xsimd::batch<double, xsimd::fma3<xsimd::avx2>>>) {
    return _mm256_i32gather_pd(base, _mm_loadu_si128(reinterpret_cast<const __m128i*>(index)), 8);
#endif
  } else {
    alignas(64) T lanes[Lane<V>::width];
    for (std::size_t l = 0; l < Lane<V>::width; ++l) lanes[l] = base[index[l]];
    return V::load_aligned(lanes);
  }
}

#if defined(KINEMA_RELAXED_FMA)
// The opt-in relaxed build of the scalar and SSE2 paths: a multiply then an add (two
// roundings). Faster where there is no FMA unit; no longer the other paths' bits.
template <class T>
  requires std::is_floating_point_v<T>
KINEMA_INLINE T mul_add(T a, T b, T c) {
  return a * b + c;
}
KINEMA_INLINE xsimd::batch<float, xsimd::sse2> mul_add(const xsimd::batch<float, xsimd::sse2>& a,
                                              const xsimd::batch<float, xsimd::sse2>& b,
                                              const xsimd::batch<float, xsimd::sse2>& c) {
  return a * b + c;
}
KINEMA_INLINE xsimd::batch<double, xsimd::sse2> mul_add(const xsimd::batch<double, xsimd::sse2>& a,
                                               const xsimd::batch<double, xsimd::sse2>& b,
                                               const xsimd::batch<double, xsimd::sse2>& c) {
  return a * b + c;
}
#else
// Scalar: libm's fma, the hardware instruction behind a call where the CPU has one. (The
// inline emulation below is slower here: a lone dependent chain exposes its latency.)
template <class T>
  requires std::is_floating_point_v<T>
KINEMA_INLINE T mul_add(T a, T b, T c) {
  return std::fma(a, b, c);
}

// SSE2 float: four lanes emulated at once (exact_fma.hpp), faster than four libm calls.
KINEMA_INLINE xsimd::batch<float, xsimd::sse2> mul_add(const xsimd::batch<float, xsimd::sse2>& a,
                                              const xsimd::batch<float, xsimd::sse2>& b,
                                              const xsimd::batch<float, xsimd::sse2>& c) {
  return exact_fma(__m128(a), __m128(b), __m128(c));
}

KINEMA_INLINE xsimd::batch<double, xsimd::sse2> mul_add(const xsimd::batch<double, xsimd::sse2>& a,
                                               const xsimd::batch<double, xsimd::sse2>& b,
                                               const xsimd::batch<double, xsimd::sse2>& c) {
  // SSE2 has no FMA: one correctly rounded std::fma per lane.
  using T = double;
  using B = xsimd::batch<T, xsimd::sse2>;
  alignas(16) T x[B::size], y[B::size], z[B::size];
  a.store_aligned(x);
  b.store_aligned(y);
  c.store_aligned(z);
  for (std::size_t i = 0; i < B::size; ++i) x[i] = std::fma(x[i], y[i], z[i]);
  return B::load_aligned(x);
}
#endif

#if defined(__FMA__)
KINEMA_INLINE xsimd::batch<float, xsimd::fma3<xsimd::avx2>> mul_add(
    const xsimd::batch<float, xsimd::fma3<xsimd::avx2>>& a,
    const xsimd::batch<float, xsimd::fma3<xsimd::avx2>>& b,
    const xsimd::batch<float, xsimd::fma3<xsimd::avx2>>& c) {
  return _mm256_fmadd_ps(a, b, c);
}
KINEMA_INLINE xsimd::batch<double, xsimd::fma3<xsimd::avx2>> mul_add(
    const xsimd::batch<double, xsimd::fma3<xsimd::avx2>>& a,
    const xsimd::batch<double, xsimd::fma3<xsimd::avx2>>& b,
    const xsimd::batch<double, xsimd::fma3<xsimd::avx2>>& c) {
  return _mm256_fmadd_pd(a, b, c);
}
#endif

#if defined(__AVX512F__)
// xsimd 8.1's fma on avx512f batches is a multiply then an add: use the instruction.
KINEMA_INLINE xsimd::batch<float, xsimd::avx512f> mul_add(const xsimd::batch<float, xsimd::avx512f>& a,
                                                 const xsimd::batch<float, xsimd::avx512f>& b,
                                                 const xsimd::batch<float, xsimd::avx512f>& c) {
  return _mm512_fmadd_ps(a, b, c);
}
KINEMA_INLINE xsimd::batch<double, xsimd::avx512f> mul_add(
    const xsimd::batch<double, xsimd::avx512f>& a, const xsimd::batch<double, xsimd::avx512f>& b,
    const xsimd::batch<double, xsimd::avx512f>& c) {
  return _mm512_fmadd_pd(a, b, c);
}
#endif

template <class T>
  requires std::is_floating_point_v<T>
KINEMA_INLINE T root(T x) {
  return std::sqrt(x);
}
template <class T, class A>
KINEMA_INLINE xsimd::batch<T, A> root(const xsimd::batch<T, A>& x) {
  return xsimd::sqrt(x);
}

// An approximation of 1 / sqrt(x) for float lanes: the reciprocal square root instruction
// (relative error below 2^-14 on AVX-512, 1.5 * 2^-12 on SSE2 and AVX2; its bits are the
// CPU's own); the scalar path divides by the exact root.
KINEMA_INLINE float rough_inverse_root(float x) { return 1.0f / std::sqrt(x); }
KINEMA_INLINE xsimd::batch<float, xsimd::sse2> rough_inverse_root(const xsimd::batch<float, xsimd::sse2>& x) {
  return _mm_rsqrt_ps(x);
}
#if defined(__AVX2__)
KINEMA_INLINE xsimd::batch<float, xsimd::fma3<xsimd::avx2>> rough_inverse_root(
    const xsimd::batch<float, xsimd::fma3<xsimd::avx2>>& x) {
  return _mm256_rsqrt_ps(x);
}
#endif
#if defined(__AVX512F__)
KINEMA_INLINE xsimd::batch<float, xsimd::avx512f> rough_inverse_root(const xsimd::batch<float, xsimd::avx512f>& x) {
  return _mm512_rsqrt14_ps(x);
}
#endif

template <class T>
  requires std::is_floating_point_v<T>
KINEMA_INLINE T pick(bool mask, T a, T b) {
  return mask ? a : b;
}
template <class T, class A>
KINEMA_INLINE xsimd::batch<T, A> pick(const xsimd::batch_bool<T, A>& mask, const xsimd::batch<T, A>& a,
                               const xsimd::batch<T, A>& b) {
  return xsimd::select(mask, a, b);
}

// The smaller and the larger of two values, lane by lane (which one a NaN gives is left open:
// for bounds only).
template <class T>
  requires std::is_floating_point_v<T>
KINEMA_INLINE T lane_min(T a, T b) {
  return a < b ? a : b;
}
template <class T>
  requires std::is_floating_point_v<T>
KINEMA_INLINE T lane_max(T a, T b) {
  return a > b ? a : b;
}
template <class T, class A>
KINEMA_INLINE xsimd::batch<T, A> lane_min(const xsimd::batch<T, A>& a, const xsimd::batch<T, A>& b) {
  return xsimd::min(a, b);
}
template <class T, class A>
KINEMA_INLINE xsimd::batch<T, A> lane_max(const xsimd::batch<T, A>& a, const xsimd::batch<T, A>& b) {
  return xsimd::max(a, b);
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
