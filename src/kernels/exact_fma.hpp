#pragma once
// Correctly rounded float fma without an FMA unit, for the scalar and SSE2 paths.
//
// a*b is exact in double (24 + 24 bits <= 53). The sum a*b + c is rounded to double
// "to odd" (truncated, last bit forced to 1 when inexact); rounding that to float is then
// the correctly rounded a*b + c, because 53 >= 2 * 24 + 2 (Boldo and Melquiond, "Emulation
// of FMA and correctly rounded sums: proved algorithms using rounding to odd", 2008).
// Round to odd comes from the round-to-nearest sum s and its exact error e (TwoSum): when
// e != 0, step s one ulp toward zero if it was rounded away from zero, then set bit 0.
// The functions are static: each per-ISA unit keeps its own copy, compiled with its flags.

#include <bit>
#include <cmath>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kinema::kernels {

static inline float exact_fma(float a, float b, float c) {
  const double p = double(a) * double(b), cd = c;
  const double s = p + cd;
  const double shift = s - p;
  const double e = (p - (s - shift)) + (cd - shift);
  if (e == 0 || !std::isfinite(s)) return float(s);
  std::uint64_t bits = std::bit_cast<std::uint64_t>(s);
  if ((e < 0) != (s < 0)) bits -= 1;
  return float(std::bit_cast<double>(bits | 1));
}

#if defined(__SSE2__)
// Two lanes of the above, a, b and c widened from float.
static inline __m128d exact_fma_odd(__m128d a, __m128d b, __m128d c) {
  const __m128d zero = _mm_setzero_pd();
  const __m128d p = _mm_mul_pd(a, b), s = _mm_add_pd(p, c);
  const __m128d shift = _mm_sub_pd(s, p);
  const __m128d e = _mm_add_pd(_mm_sub_pd(p, _mm_sub_pd(s, shift)), _mm_sub_pd(c, shift));
  const __m128d finite = _mm_cmpeq_pd(_mm_sub_pd(s, s), zero);
  const __m128i inexact = _mm_castpd_si128(_mm_and_pd(_mm_cmpneq_pd(e, zero), finite));
  const __m128i away =
      _mm_castpd_si128(_mm_xor_pd(_mm_cmplt_pd(e, zero), _mm_cmplt_pd(s, zero)));
  __m128i bits = _mm_add_epi64(_mm_castpd_si128(s), _mm_and_si128(away, inexact));  // -1
  bits = _mm_or_si128(bits, _mm_and_si128(inexact, _mm_set1_epi64x(1)));
  return _mm_castsi128_pd(bits);
}

static inline __m128 exact_fma(__m128 a, __m128 b, __m128 c) {
  const __m128d lo = exact_fma_odd(_mm_cvtps_pd(a), _mm_cvtps_pd(b), _mm_cvtps_pd(c));
  const __m128d hi = exact_fma_odd(_mm_cvtps_pd(_mm_movehl_ps(a, a)),
                                   _mm_cvtps_pd(_mm_movehl_ps(b, b)),
                                   _mm_cvtps_pd(_mm_movehl_ps(c, c)));
  return _mm_movelh_ps(_mm_cvtpd_ps(lo), _mm_cvtpd_ps(hi));
}
#endif

}  // namespace kinema::kernels
