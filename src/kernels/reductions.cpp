// The reductions of reductions.hpp, cloned per instruction set with the same operations in
// each.
#include "kernels/reductions.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "kernels/cloned.hpp"
#include "kinema/methods.hpp"

namespace kinema {
namespace {

// sum over i < n of (e_i / (atol + rtol max(|y0_i|, |y1_i|)))^2, e_i = sum_s w_s k_s[i], in
// double: the terms go to 16 running sums (term i to sum i % 16), added in order at the end.
// Every clone does the same operations in the same order (no fused multiply-add: the library
// builds with -ffp-contract=off), so the norm, and the steps it decides, are the same on
// every instruction set; the clones only do more of them at once.
// A term is 0 where e is 0 (with atol 0, a component that stays 0 would give 0 / 0), and
// infinite where the new value is not finite: a candidate that overflowed is never accepted.
template <int S, class T>
[[gnu::always_inline]] inline double lane_term(const T* y0, const T* y1, const T* const* k, const double* w,
                                               double rtol, double atol, std::size_t i) {
  double e = w[0] * double(k[0][i]);
  for (int s = 1; s < S; ++s) e += w[s] * double(k[s][i]);
  const double y = double(y1[i]);
  const double scale = atol + rtol * std::max(std::abs(double(y0[i])), std::abs(y));
  const double q = e == 0 ? 0.0 : e / scale;
  return std::abs(y) <= std::numeric_limits<double>::max() ? q * q : std::numeric_limits<double>::infinity();
}

template <int S, class T>
[[gnu::always_inline]] inline double squares_of(const T* y0, const T* y1, const T* const* k, const double* w,
                                                double rtol, double atol, std::size_t n) {
  constexpr std::size_t kLanes = 16;
  double sums[kLanes] = {};
  std::size_t i = 0;
  for (; i + kLanes <= n; i += kLanes) {
    for (std::size_t l = 0; l < kLanes; ++l) sums[l] += lane_term<S>(y0, y1, k, w, rtol, atol, i + l);
  }
  for (std::size_t l = 0; i + l < n; ++l) sums[l] += lane_term<S>(y0, y1, k, w, rtol, atol, i + l);
  double total = 0;
  for (double x : sums) total += x;
  return total;
}

template <class T>
[[gnu::always_inline]] inline double weighted_squares(const T* y0, const T* y1, const T* const* k, const double* w,
                                                      int stages, double rtol, double atol, std::size_t n) {
  static_assert(kMaxStages == 7);
  switch (stages) {  // a stage count known at compile time unrolls the sum over stages
    case 1: return squares_of<1>(y0, y1, k, w, rtol, atol, n);
    case 2: return squares_of<2>(y0, y1, k, w, rtol, atol, n);
    case 3: return squares_of<3>(y0, y1, k, w, rtol, atol, n);
    case 4: return squares_of<4>(y0, y1, k, w, rtol, atol, n);
    case 5: return squares_of<5>(y0, y1, k, w, rtol, atol, n);
    case 6: return squares_of<6>(y0, y1, k, w, rtol, atol, n);
    default: return squares_of<7>(y0, y1, k, w, rtol, atol, n);
  }
}

}  // namespace

KINEMA_CLONED double error_squares(const float* y0, const float* y1, const float* const* k, const double* w,
                                   int stages, double rtol, double atol, std::size_t n) {
  return weighted_squares(y0, y1, k, w, stages, rtol, atol, n);
}
KINEMA_CLONED double error_squares(const double* y0, const double* y1, const double* const* k, const double* w,
                                   int stages, double rtol, double atol, std::size_t n) {
  return weighted_squares(y0, y1, k, w, stages, rtol, atol, n);
}

namespace {

template <class T>
[[gnu::always_inline]] inline double scaled_squares_of(const T* a, const T* w, double scale, double rtol, double atol,
                                                       std::size_t n) {
  constexpr std::size_t kLanes = 16;
  double sums[kLanes] = {};
  const auto term = [&](std::size_t i) {
    const double q = a[i] == 0 ? 0.0 : double(a[i]) * scale / (atol + rtol * std::abs(double(w[i])));
    return q * q;
  };
  std::size_t i = 0;
  for (; i + kLanes <= n; i += kLanes) {
    for (std::size_t l = 0; l < kLanes; ++l) sums[l] += term(i + l);
  }
  for (std::size_t l = 0; i + l < n; ++l) sums[l] += term(i + l);
  double total = 0;
  for (double x : sums) total += x;
  return total;
}

}  // namespace

KINEMA_CLONED double scaled_squares(const float* a, const float* w, double scale, double rtol, double atol,
                                   std::size_t n) {
  return scaled_squares_of(a, w, scale, rtol, atol, n);
}
KINEMA_CLONED double scaled_squares(const double* a, const double* w, double scale, double rtol, double atol,
                                   std::size_t n) {
  return scaled_squares_of(a, w, scale, rtol, atol, n);
}

// A value is not finite when its exponent bits are all ones; adding the exponent's lowest
// bit then carries into the sign bit. The OR of those sums over an array says whether any
// value is not finite, in a loop that vectorizes: cloned per instruction set (the answer is
// the same on each), since the scan runs after every call of a guarded stepper. The bits are
// read through types allowed to alias float and double.
namespace {
using FloatBits [[gnu::may_alias]] = std::uint32_t;
using DoubleBits [[gnu::may_alias]] = std::uint64_t;
}  // namespace

KINEMA_CLONED bool any_not_finite(const float* values, std::size_t n) {
  const auto* a = reinterpret_cast<const FloatBits*>(values);
  std::uint32_t carries = 0;
  for (std::size_t i = 0; i < n; ++i) carries |= (a[i] & 0x7F800000u) + 0x00800000u;
  return (carries >> 31) != 0;
}
KINEMA_CLONED bool any_not_finite(const double* values, std::size_t n) {
  const auto* a = reinterpret_cast<const DoubleBits*>(values);
  std::uint64_t carries = 0;
  for (std::size_t i = 0; i < n; ++i) carries |= (a[i] & 0x7FF0000000000000ull) + 0x0010000000000000ull;
  return (carries >> 63) != 0;
}

// Many arrays in one pass: the largest exponent field, three arrays a loop (one max chain
// each iteration instead of an OR chain per array and a call per array), is all ones exactly
// when some value is not finite.
namespace {
template <class Bits, class T>
[[gnu::always_inline]] inline bool any_exponent_full(const T* const* arrays, int count, std::size_t begin,
                                                     std::size_t end, Bits exponent) {
  const auto field = [exponent](T value) { return Bits(std::bit_cast<Bits>(value) & exponent); };
  Bits top = 0;
  int k = 0;
  for (; k + 3 <= count; k += 3) {
    const T *p = arrays[k], *q = arrays[k + 1], *r = arrays[k + 2];
    for (std::size_t i = begin; i < end; ++i) top = std::max(top, std::max(field(p[i]), std::max(field(q[i]), field(r[i]))));
  }
  for (; k < count; ++k) {
    for (std::size_t i = begin; i < end; ++i) top = std::max(top, field(arrays[k][i]));
  }
  return top == exponent;
}
}  // namespace

KINEMA_CLONED bool any_not_finite(const float* const* arrays, int count, std::size_t begin, std::size_t end) {
  return any_exponent_full<std::uint32_t>(arrays, count, begin, end, 0x7F800000u);
}
KINEMA_CLONED bool any_not_finite(const double* const* arrays, int count, std::size_t begin, std::size_t end) {
  return any_exponent_full<std::uint64_t>(arrays, count, begin, end, 0x7FF0000000000000ull);
}

}  // namespace kinema
