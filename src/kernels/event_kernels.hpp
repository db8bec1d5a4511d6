#pragma once
// The events' sign test: each body's event value at both ends of a step, compared lane by
// lane; only the lanes of a batch that crossed are looked at one by one. The values use
// mul_add as written, so every instruction set finds the same bodies. The fused kernels run
// a superset of it on the values they hold (probe_crossed, or a band about a plane along an
// axis: EventScanJob::band), so they list every batch where a body may have crossed;
// event_scan runs the exact test on arrays.

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "kernels/kernels.hpp"
#include "kernels/wide.hpp"

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
  // The value of bodies at positions x and velocities v.
  KINEMA_INLINE V value(const V (&x)[3], const V (&v)[3]) const {
    if constexpr (K == EventValue::axis_plane) {
      // The plane's value with its zero terms left out. Picked by branches, not x[axis]:
      // indexing by a run-time value would send the fused kernels' registers to memory.
      V along = x[2], normal = a[2];
      if (axis == 0) along = x[0], normal = a[0];
      if (axis == 1) along = x[1], normal = a[1];
      return normal * along - b;
    } else if constexpr (K == EventValue::plane) {
      return mul_add(a[2], x[2], mul_add(a[1], x[1], a[0] * x[0])) - b;
    } else {
      V d[3];
      for (int c = 0; c < 3; ++c) d[c] = K == EventValue::speed ? v[c] : x[c] - a[c];
      return mul_add(d[2], d[2], mul_add(d[1], d[1], d[0] * d[0])) - b;
    }
  }
  // The value of the bodies at i of the arrays s (px .. vz); only the arrays it needs are read.
  KINEMA_INLINE V value(const value_t<V>* const s[6], std::size_t i) const {
    if constexpr (K == EventValue::given) return load<V>(s[0] + i);
    V x[3], v[3];
    for (int c = 0; c < 3; ++c) {
      const bool reads_x = K == EventValue::plane || K == EventValue::distance || (K == EventValue::axis_plane && c == axis);
      x[c] = reads_x ? load<V>(s[c] + i) : V(0);
      v[c] = K == EventValue::speed ? load<V>(s[3 + c] + i) : V(0);
    }
    return value(x, v);
  }
  // Whether a lane's value changed sign the way the event counts.
  template <class L>
  KINEMA_INLINE auto crossed(const L& g0, const L& g1) const {
    const L zero(0);
    if (down && up) return ((g0 > zero) & (g1 <= zero)) | ((g0 < zero) & (g1 >= zero));
    if (down) return (g0 > zero) & (g1 <= zero);
    return (g0 < zero) & (g1 >= zero);
  }
  KINEMA_INLINE auto crossed(const V (&x0)[3], const V (&v0)[3], const V (&x1)[3], const V (&v1)[3]) const {
    return crossed(value(x0, v0), value(x1, v1));
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

// The lanes of a mask as bits, lane l at bit l.
template <class M>
KINEMA_INLINE std::uint32_t lane_bits(const M& mask) {
  if constexpr (std::is_integral_v<M> || std::is_same_v<M, bool>) {
    return mask ? 1u : 0u;
  } else {
    const typename M::register_type bits(mask);
    if constexpr (sizeof(typename M::register_type) <= 2) {
      return std::uint32_t(bits);  // AVX-512: a mask register already
    } else if constexpr (sizeof(bits) == 32) {
      if constexpr (sizeof(typename M::batch_type::value_type) == 4) return std::uint32_t(_mm256_movemask_ps(bits));
      else return std::uint32_t(_mm256_movemask_pd(bits));
    } else {
      if constexpr (sizeof(typename M::batch_type::value_type) == 4) return std::uint32_t(_mm_movemask_ps(bits));
      else return std::uint32_t(_mm_movemask_pd(bits));
    }
  }
}

// Whether any body of a batch may have crossed one of the probe's events over its step from
// (x0, v0) to (x1, v1): the values of event_scan, on registers, tested for a sign change in
// either direction (g0 g1 <= 0, a superset of every direction's test: an underflow to 0 only
// adds a batch). One branch per batch; event_scan then applies the direction.
template <EventValue K, class V, class Mask>
KINEMA_INLINE void probe_one(const EventScanJob<value_t<V>>& t, const V (&x0)[3], const V (&v0)[3], const V (&x1)[3],
                             const V (&v1)[3], Mask& mask) {
  const EventTest<K, V> test(t);
  mask = mask | (test.value(x0, v0) * test.value(x1, v1) <= V(0));
}

template <class V>
KINEMA_INLINE bool probe_crossed(const EventProbe<value_t<V>>& probe, const V (&x0)[3], const V (&v0)[3],
                                 const V (&x1)[3], const V (&v1)[3]) {
  auto mask = V(0) != V(0);
  for (int e = 0; e < probe.count; ++e) {
    const EventScanJob<value_t<V>>& t = probe.tests[e];
    if (t.value == EventValue::axis_plane) {
      probe_one<EventValue::axis_plane>(t, x0, v0, x1, v1, mask);
    } else if (t.value == EventValue::plane) {
      probe_one<EventValue::plane>(t, x0, v0, x1, v1, mask);
    } else if (t.value == EventValue::distance) {
      probe_one<EventValue::distance>(t, x0, v0, x1, v1, mask);
    } else {
      probe_one<EventValue::speed>(t, x0, v0, x1, v1, mask);
    }
  }
  return any_lane(mask);
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
    // The lanes that crossed, lowest first, without a branch per lane.
    for (std::uint32_t bits = lane_bits(test.crossed(g0, g1)); bits != 0; bits &= bits - 1) {
      found[n++] = std::uint32_t(i + unsigned(__builtin_ctz(bits)));
    }
  }
  return n;
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
