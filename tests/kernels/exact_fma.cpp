// The float fma emulation of the scalar and SSE2 paths is correctly rounded: it agrees with
// std::fma on random and on hand-picked hard cases.
#include <catch2/catch.hpp>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

#include "kernels/exact_fma.hpp"

using kinema::kernels::exact_fma;

namespace {

bool same(float a, float b) {
  return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b) ||
         (std::isnan(a) && std::isnan(b));
}

float sse2_lane(float a, float b, float c) {
  alignas(16) float out[4];
  _mm_store_ps(out, exact_fma(_mm_set1_ps(a), _mm_set1_ps(b), _mm_set1_ps(c)));
  return out[1];
}

void check(float a, float b, float c) {
  const float expected = std::fma(a, b, c);
  INFO(a << " * " << b << " + " << c);
  REQUIRE(same(exact_fma(a, b, c), expected));
  REQUIRE(same(sse2_lane(a, b, c), expected));
}

}  // namespace

TEST_CASE("exact_fma matches std::fma on random operands", "[exact_fma]") {
  std::mt19937 rng(12345);
  std::uniform_int_distribution<std::uint32_t> bits;
  for (int i = 0; i < 200000; ++i) {
    // Random bit patterns cover every exponent, subnormals, infinities and NaNs.
    check(std::bit_cast<float>(bits(rng)), std::bit_cast<float>(bits(rng)),
          std::bit_cast<float>(bits(rng)));
  }
  std::uniform_real_distribution<float> unit(-2, 2);
  for (int i = 0; i < 200000; ++i) {
    const float a = unit(rng), b = unit(rng);
    check(a, b, -a * b);  // massive cancellation: the product's rounding error is the result
    check(a, b, unit(rng));
  }
}

TEST_CASE("exact_fma gets the hard cases right", "[exact_fma]") {
  const float eps = std::numeric_limits<float>::epsilon();
  const float tiny = std::numeric_limits<float>::denorm_min();
  const float big = std::numeric_limits<float>::max();
  const float inf = std::numeric_limits<float>::infinity();
  check(1.0001f, 0.9999f, -1.0f);                 // the fused result is -1.00033e-08
  check(1 + eps, 1 - eps, -1.0f);                  // -eps^2: lost without fusion
  check(1 + eps, 1 + eps, -(1 + 2 * eps));         // eps^2 exactly
  check(0.5f + eps, 1.0f, std::ldexp(1.0f, -25));  // a tie after the sum: needs round-to-odd
  check(tiny, 0.5f, 0.0f);                          // subnormal halfway case
  check(std::ldexp(1.0f, -100), std::ldexp(1.0f, -50), tiny);
  check(big, 2.0f, -big);                           // finite: the product overflows float only
  check(big, 1.0f, big);                            // overflow to inf
  check(inf, 0.0f, 1.0f);                           // NaN
  check(-0.0f, 1.0f, 0.0f);                         // signed zeros
  check(-0.0f, 1.0f, -0.0f);
}
