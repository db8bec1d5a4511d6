#pragma once
// Reductions over whole arrays that run after every step or attempt: the error-controlled
// driver's sums of squares and the finiteness guard's scan. Each is compiled once per
// instruction set (kernels/cloned.hpp) with the same operations in every clone, so the
// answer is the same bits on every CPU.

#include <cstddef>

namespace kinema {

// sum over i < n of (e_i / (atol + rtol max(|y0_i|, |y1_i|)))^2 with e_i = sum over the
// stages of w_s k_s[i], in double; the same bits on every instruction set.
double error_squares(const float* y0, const float* y1, const float* const* k, const double* w, int stages,
                     double rtol, double atol, std::size_t n);
double error_squares(const double* y0, const double* y1, const double* const* k, const double* w, int stages,
                     double rtol, double atol, std::size_t n);
// sum over i < n of (a_i scale / (atol + rtol |w_i|))^2, in double, likewise.
double scaled_squares(const float* a, const float* w, double scale, double rtol, double atol, std::size_t n);
double scaled_squares(const double* a, const double* w, double scale, double rtol, double atol, std::size_t n);

// True when any of values[0 .. n) is not finite.
bool any_not_finite(const float* values, std::size_t n);
bool any_not_finite(const double* values, std::size_t n);
// True when any of arrays[0 .. count)[begin, end) is not finite, in one pass.
bool any_not_finite(const float* const* arrays, int count, std::size_t begin, std::size_t end);
bool any_not_finite(const double* const* arrays, int count, std::size_t begin, std::size_t end);

}  // namespace kinema
