#pragma once
// The events' sign test: each body's event value at both ends of a step, compared lane by
// lane; only the lanes of a batch that crossed are looked at one by one. The values use
// mul_add as written, so every instruction set finds the same bodies.

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "kernels/kernel_impl.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

template <EventValue K, class V>
KINEMA_INLINE V event_value(const EventScanJob<value_t<V>>& job, const value_t<V>* const s[6], std::size_t i) {
  const V b(job.b);
  if constexpr (K == EventValue::plane) {
    const V along = mul_add(V(job.a[1]), load<V>(s[1] + i), V(job.a[0]) * load<V>(s[0] + i));
    return mul_add(V(job.a[2]), load<V>(s[2] + i), along) - b;
  } else {
    constexpr int first = K == EventValue::speed ? 3 : 0;
    V d[3];
    for (int c = 0; c < 3; ++c) {
      d[c] = load<V>(s[first + c] + i);
      if constexpr (K == EventValue::distance) d[c] = d[c] - V(job.a[c]);
    }
    return mul_add(d[2], d[2], mul_add(d[1], d[1], d[0] * d[0])) - b;
  }
}

template <class V>
KINEMA_INLINE auto crossed(const EventScanJob<value_t<V>>& job, const V& g0, const V& g1) {
  const V zero(0);
  const auto down = (g0 > zero) & (g1 <= zero);
  const auto up = (g0 < zero) & (g1 >= zero);
  return job.down ? (job.up ? (down | up) : down) : up;
}

template <class M>
KINEMA_INLINE bool any_lane(const M& mask) {
  if constexpr (std::is_integral_v<M> || std::is_same_v<M, bool>) {
    return mask != 0;
  } else {
    return xsimd::any(mask);
  }
}

template <EventValue K, class V>
std::size_t event_scan(const EventScanJob<value_t<V>>& job, std::size_t count, std::uint32_t* found) {
  using T = value_t<V>;
  constexpr std::size_t width = Lane<V>::width;
  std::size_t n = 0;
  for (std::size_t i = 0; i < count; i += width) {
    const V g0 = event_value<K, V>(job, job.before, i), g1 = event_value<K, V>(job, job.after, i);
    if (!any_lane(crossed<V>(job, g0, g1))) continue;
    alignas(64) T before[width], after[width];
    store(before, g0);
    store(after, g1);
    for (std::size_t l = 0; l < width; ++l) {
      if (any_lane(crossed<T>(job, before[l], after[l]))) found[n++] = std::uint32_t(i + l);
    }
  }
  return n;
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
