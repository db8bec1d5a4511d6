#pragma once
// The events' sign test: each body's event value at both ends of a step, compared lane by
// lane; only the lanes of a batch that crossed are looked at one by one. The values use
// mul_add as written, so every instruction set finds the same bodies.

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "kernels/kernel_impl.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

// The job's constants, broadcast once per call.
template <EventValue K, class V>
struct EventTest {
  V a[3], b;
  bool down, up;
  int axis;

  explicit EventTest(const EventScanJob<value_t<V>>& job) : b(job.b), down(job.down), up(job.up), axis(job.axis) {
    for (int d = 0; d < 3; ++d) a[d] = V(job.a[d]);
  }
  // The value of the bodies at i of the arrays s (px .. vz).
  KINEMA_INLINE V value(const value_t<V>* const s[6], std::size_t i) const {
    if constexpr (K == EventValue::axis_plane) {
      return a[axis] * load<V>(s[axis] + i) - b;  // the plane's value with its zero terms left out
    } else if constexpr (K == EventValue::plane) {
      const V along = mul_add(a[1], load<V>(s[1] + i), a[0] * load<V>(s[0] + i));
      return mul_add(a[2], load<V>(s[2] + i), along) - b;
    } else {
      constexpr int first = K == EventValue::speed ? 3 : 0;
      V d[3];
      for (int c = 0; c < 3; ++c) {
        d[c] = load<V>(s[first + c] + i);
        if constexpr (K == EventValue::distance) d[c] = d[c] - a[c];
      }
      return mul_add(d[2], d[2], mul_add(d[1], d[1], d[0] * d[0])) - b;
    }
  }
  // Whether a lane's value changed sign the way the event counts.
  template <class L>
  KINEMA_INLINE auto crossed(const L& g0, const L& g1) const {
    const L zero(0);
    if (down && up) return ((g0 > zero) & (g1 <= zero)) | ((g0 < zero) & (g1 >= zero));
    if (down) return (g0 > zero) & (g1 <= zero);
    return (g0 < zero) & (g1 >= zero);
  }
};

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
  const EventTest<K, V> test(job);
  const T* const before[6] = {job.before[0], job.before[1], job.before[2], job.before[3], job.before[4], job.before[5]};
  const T* const after[6] = {job.after[0], job.after[1], job.after[2], job.after[3], job.after[4], job.after[5]};
  std::size_t n = 0;
  for (std::size_t i = 0; i < count; i += width) {
    const V g0 = test.value(before, i), g1 = test.value(after, i);
    if (!any_lane(test.crossed(g0, g1))) continue;
    alignas(64) T start[width], end[width];
    store(start, g0);
    store(end, g1);
    for (std::size_t l = 0; l < width; ++l) {
      if (any_lane(test.crossed(start[l], end[l]))) found[n++] = std::uint32_t(i + l);
    }
  }
  return n;
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
