// The sums of squares the error norm of the error-controlled driver takes, cloned per
// instruction set with the same operations in each (see weighted_squares).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

#include "cloned.hpp"
#include "error_control.hpp"
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

KINEMA_CLONED double error_squares(const float* y0, const float* y1,
                                                                         const float* const* k, const double* w,
                                                                         int stages, double rtol, double atol,
                                                                         std::size_t n) {
  return weighted_squares(y0, y1, k, w, stages, rtol, atol, n);
}
KINEMA_CLONED double error_squares(const double* y0, const double* y1,
                                                                         const double* const* k, const double* w,
                                                                         int stages, double rtol, double atol,
                                                                         std::size_t n) {
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

KINEMA_CLONED double scaled_squares(const float* a, const float* w, double scale,
                                                                          double rtol, double atol, std::size_t n) {
  return scaled_squares_of(a, w, scale, rtol, atol, n);
}
KINEMA_CLONED double scaled_squares(const double* a, const double* w,
                                                                          double scale, double rtol, double atol,
                                                                          std::size_t n) {
  return scaled_squares_of(a, w, scale, rtol, atol, n);
}

}  // namespace kinema
