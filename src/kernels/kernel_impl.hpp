#pragma once
// The kernels, written once over a lane type V (a scalar T or an xsimd batch) and
// instantiated per instruction set by kernels_<isa>.cpp, each inside its own namespace.

#include <array>
#include <cstddef>
#include <utility>

#include "kernels/event_kernels.hpp"
#include "kernels/kernels.hpp"
#include "kernels/wide.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

template <int N, class F>
KINEMA_INLINE void static_for(F&& f) {
  [&]<int... I>(std::integer_sequence<int, I...>) {
    (f(std::integral_constant<int, I>{}), ...);
  }(std::make_integer_sequence<int, N>{});
}

// A vector quantity of N components (positions, velocities: 3; quaternions: 4), one
// lane type each: SoA in registers.
template <class V, int N = 3>
struct Vec {
  V c[N];
};

template <int N, class V>
KINEMA_INLINE Vec<V, N> load_n(const value_t<V>* const p[N], std::size_t i) {
  Vec<V, N> v;
  for (int d = 0; d < N; ++d) v.c[d] = load<V>(p[d] + i);
  return v;
}
template <int N, class V>
KINEMA_INLINE void store_n(value_t<V>* const p[N], std::size_t i, const Vec<V, N>& v) {
  for (int d = 0; d < N; ++d) store(p[d] + i, v.c[d]);
}
template <class V>
KINEMA_INLINE Vec<V> load3(const value_t<V>* const p[3], std::size_t i) {
  return load_n<3, V>(p, i);
}
template <class V>
KINEMA_INLINE void store3(value_t<V>* const p[3], std::size_t i, const Vec<V>& v) {
  store_n<3, V>(p, i, v);
}

// The local force terms, broadcast to lanes once per call, each multiplied by `scale` (the
// accelerations come out scaled: see acceleration_scale in kernels.hpp).
template <class V>
struct Forces {
  using T = value_t<V>;
  V g[3], force[3], anchor[3], neg_spring_k, neg_linear, neg_quadratic, scale;
  int central_count;
  V center[4][3], neg_mu[4];

  explicit Forces(const LocalForces<T>& f, T scale = 1)
      : neg_spring_k(-(f.spring_k * scale)), neg_linear(-(f.linear * scale)),
        neg_quadratic(-(f.quadratic * scale)), scale(scale), central_count(f.central_count) {
    for (int d = 0; d < 3; ++d) {
      g[d] = V(f.gravity[d] * scale);
      force[d] = V(f.constant_force[d] * scale);
      anchor[d] = V(f.anchor[d]);
    }
    for (int c = 0; c < central_count; ++c) {
      for (int d = 0; d < 3; ++d) center[c][d] = V(f.center[c][d]);
      neg_mu[c] = V(-(f.mu[c] * scale));
    }
  }
};

// What a body's acceleration needs besides its state, formed once per body per call:
// the mass-scaled coefficients and gravity, all zero for bodies with inv_mass 0, so the
// stages need no mask except for central terms.
template <class V, class M>
struct BodyTerms {
  V neg_k, neg_linear, neg_quadratic;  // -inv_mass * (spring k, linear, quadratic drag)
  V g[3];
  M dynamic;
};

// `Pushed`: add the constant force of the point-force terms (rigid bodies only).
template <bool Pushed = false, class V>
KINEMA_INLINE auto body_terms(const Forces<V>& f, const V& inv_mass) {
  const auto dynamic = inv_mass != V(0);
  BodyTerms<V, decltype(dynamic)> b{f.neg_spring_k * inv_mass, f.neg_linear * inv_mass,
                                    f.neg_quadratic * inv_mass, {}, dynamic};
  for (int d = 0; d < 3; ++d) {
    b.g[d] = pick(dynamic, Pushed ? mul_add(inv_mass, f.force[d], f.g[d]) : f.g[d], V(0));
  }
  return b;
}

// The forces applied to single bodies (constant over the call) join their constant
// acceleration: g + inv_mass (scale F), still zero where inv_mass is 0.
template <class V, class B>
KINEMA_INLINE void add_applied(B& body, const Forces<V>& f, const V& inv_mass, const Vec<V>& force) {
  for (int d = 0; d < 3; ++d) {
    body.g[d] = pick(body.dynamic, mul_add(inv_mass, f.scale * force.c[d], body.g[d]), V(0));
  }
}

// Whether a kernel reads the bodies' own forces and parameters: never (a plain fused
// variant), or those the set has (tested once per batch).
enum class Applied { never, if_present };

// The fused particle kernels' variants: plain, with central terms (and the bodies' own forces
// and parameters where present), with the bodies' own forces and parameters. A model pays
// only for what it uses.
template <int Variant>
inline constexpr bool has_central = Variant == kCentralVariant;
template <int Variant>
inline constexpr Applied reads_applied = Variant == kPlainVariant ? Applied::never : Applied::if_present;

// The body's own parameters, where its set has them: gravity times its factor (ahead of the
// point forces' push, as body_terms forms it) and its damping rate joined to the drag.
template <bool Pushed, class V, class B, class T>
KINEMA_INLINE void add_parameters(B& body, const Forces<V>& f, const V& inv_mass, const PerBody<T>& p,
                                  std::size_t i) {
  if (p.gravity_factor != nullptr) {
    const V factor = load<V>(p.gravity_factor + i);
    for (int d = 0; d < 3; ++d) {
      const V g = factor * f.g[d];
      body.g[d] = pick(body.dynamic, Pushed ? mul_add(inv_mass, f.force[d], g) : g, V(0));
    }
  }
  if (p.linear_damping != nullptr) {
    const V rate = load<V>(p.linear_damping + i);
    body.neg_linear = pick(body.dynamic, mul_add(V(0) - f.scale, rate, body.neg_linear), V(0));
  }
}

// body_terms, plus the body's parameters and applied forces where its set has them and A
// reads them.
template <Applied A, bool Pushed = false, class V, class T>
KINEMA_INLINE auto body_terms_at(const Forces<V>& f, const V& inv_mass, const PerBody<T>& p, std::size_t i) {
  auto body = body_terms<Pushed>(f, inv_mass);
  if constexpr (A == Applied::if_present) {
    add_parameters<Pushed>(body, f, inv_mass, p, i);
    if (p.applied[0] != nullptr) add_applied(body, f, inv_mass, load3<V>(p.applied, i));
  }
  return body;
}

// Position relative to the springs' anchor.
template <class V>
KINEMA_INLINE Vec<V> anchored(const Forces<V>& f, const Vec<V>& x) {
  Vec<V> r;
  for (int d = 0; d < 3; ++d) r.c[d] = x.c[d] - f.anchor[d];
  return r;
}

// The part of the acceleration linear in position: g - (k / m) xr, xr the anchor offset.
template <class V, class B>
KINEMA_INLINE Vec<V> linear_part(const B& body, const Vec<V>& xr) {
  Vec<V> p;
  for (int d = 0; d < 3; ++d) p.c[d] = mul_add(body.neg_k, xr.c[d], body.g[d]);
  return p;
}

// The linear part at a Runge-Kutta stage position x + step * sum, from its value at x:
// p + (-k / m) step sum. Exact in real arithmetic, it skips forming the stage position (one
// fma per component instead of two, and a shorter chain from one stage to the next).
template <class V, class B>
KINEMA_INLINE Vec<V> linear_part_at(const B& body, value_t<V> step, const Vec<V>& sum,
                                    const Vec<V>& p) {
  const V slope = body.neg_k * V(step);
  Vec<V> out;
  for (int d = 0; d < 3; ++d) out.c[d] = mul_add(slope, sum.c[d], p.c[d]);
  return out;
}

// Acceleration from its linear part p, the world position x (for central terms) and the
// velocity v: the sum of the local terms, zero where inv_mass is 0.
// a = g - (k / m) (x - anchor) - ((c + q |v|) / m) v - sum mu r / |r|^3, with r = x - centre.
// The operation order is part of the contract: every path and both step paths use this.
template <bool Quadratic, bool Central, class V, class B>
KINEMA_INLINE Vec<V> accel(const Forces<V>& f, const B& body, const Vec<V>& p, const Vec<V>& x,
                           const Vec<V>& v) {
  V neg_drag = body.neg_linear;
  if constexpr (Quadratic) {
    V speed = root(mul_add(v.c[0], v.c[0], mul_add(v.c[1], v.c[1], v.c[2] * v.c[2])));
    neg_drag = mul_add(body.neg_quadratic, speed, neg_drag);
  }
  Vec<V> a;
  for (int d = 0; d < 3; ++d) a.c[d] = mul_add(neg_drag, v.c[d], p.c[d]);
  if constexpr (Central) {
    for (int c = 0; c < f.central_count; ++c) {
      Vec<V> r;
      for (int d = 0; d < 3; ++d) r.c[d] = x.c[d] - f.center[c][d];
      V r2 = mul_add(r.c[0], r.c[0], mul_add(r.c[1], r.c[1], r.c[2] * r.c[2]));
      // -mu / |r|^3; masked, as a padding body at the centre gives 0/0.
      V scale = pick(body.dynamic, f.neg_mu[c] / (r2 * root(r2)), V(0));
      for (int d = 0; d < 3; ++d) a.c[d] = mul_add(scale, r.c[d], a.c[d]);
    }
  }
  return a;
}

// accel at a state of the bodies' own (kick-drift methods, first stages).
template <bool Quadratic, bool Central, class V, class B>
KINEMA_INLINE Vec<V> accel_at(const Forces<V>& f, const B& body, const Vec<V>& x, const Vec<V>& v) {
  return accel<Quadratic, Central>(f, body, linear_part(body, anchored(f, x)), x, v);
}

// sum + ratio * k. Ratios 1 and 2 (RK4's, Heun's) become adds, which run on the FP add
// pipes while the FMA pipes are the bottleneck; the bits are those of the fma either way
// (k + k is exact, so (k + k) + sum rounds once, like fma(2, k, sum)).
template <class V>
KINEMA_INLINE V accumulate(value_t<V> ratio, const V& k, const V& sum) {
  if (ratio == 1) return sum + k;
  if (ratio == 2) return sum + (k + k);
  return mul_add(V(ratio), k, sum);
}

template <class V, int N>
KINEMA_INLINE Vec<V, N> step_by(const V& h, const Vec<V, N>& dir, const Vec<V, N>& base) {
  Vec<V, N> out;
  for (int d = 0; d < N; ++d) out.c[d] = mul_add(h, dir.c[d], base.c[d]);
  return out;
}

// base + coef * dir, by `accumulate`: an add where coef is 1.
template <class V, int N>
KINEMA_INLINE Vec<V, N> stepped(value_t<V> coef, const Vec<V, N>& dir, const Vec<V, N>& base) {
  Vec<V, N> out;
  for (int d = 0; d < N; ++d) out.c[d] = accumulate(coef, dir.c[d], base.c[d]);
  return out;
}

using Weights = std::array<double, kMaxStages>;

// G_0 + r_1 G_1 + ... for the nonzero weights of W (see RowSum in kernels.hpp).
template <Weights W, class V, int S, int N>
KINEMA_INLINE Vec<V, N> grouped_sum(const Vec<V, N> (&k)[S]) {
  constexpr TermGroups G = row_sum(W).groups;
  Vec<V, N> sum = k[G.lead[0]];
  static_for<G.count>([&](auto g) {
    constexpr int lead = G.lead[g];
    Vec<V, N> part = k[lead];
    static_for<S>([&](auto j) {
      if constexpr (j > lead && G.group[j] == g) {
        for (int d = 0; d < N; ++d) part.c[d] = part.c[d] + k[j].c[d];
      }
    });
    if constexpr (g == 0) {
      sum = part;
    } else {
      for (int d = 0; d < N; ++d) sum.c[d] = accumulate(value_t<V>(G.ratio[g]), part.c[d], sum.c[d]);
    }
  });
  return sum;
}

// base + h * sum_j w_j k_j, formed as base + (w_f h) (G_0 + r_1 G_1 + ...): one rounding
// into base. With a Divisor sigma the k are accelerations already scaled by sigma h, and
// the last step is base + (w_f / sigma) (...). The staged path's `combined` follows the
// same rule at run time.
template <Weights W, double Divisor = 0.0, class V, int S, int N>
KINEMA_INLINE Vec<V, N> advanced(value_t<V> h, const Vec<V, N> (&k)[S], const Vec<V, N>& base) {
  using T = value_t<V>;
  constexpr RowSum R = row_sum(W);
  if constexpr (R.empty()) {
    return base;
  } else if constexpr (Divisor != 0.0) {
    constexpr T step = R.velocity_step<T>(Divisor);  // a constant: no run-time test
    return stepped(step, grouped_sum<W>(k), base);
  } else {
    return step_by(V(R.position_step(h)), grouped_sum<W>(k), base);
  }
}

// The linear part of the acceleration at the stage position of row W (see linear_part_at).
template <Weights W, class V, class B, int S>
KINEMA_INLINE Vec<V> stage_linear_part(value_t<V> h, const B& body, const Vec<V> (&kx)[S],
                                       const Vec<V>& p) {
  constexpr RowSum R = row_sum(W);
  if constexpr (R.empty()) {
    return p;
  } else {
    return linear_part_at(body, R.position_step(h), grouped_sum<W>(kx), p);
  }
}

// Where a fused particle kernel reads the state: the job's source, or in place.
template <class T>
struct StateSource {
  const T* x[3];
  const T* v[3];
  T* const* before = nullptr;  // FusedJob::before
  EventProbe<T>* probe = nullptr;  // FusedJob::probe
  // A probe of one plane along an axis (a floor, a wall, EventScanJob::band): the coordinate
  // along it, read before the batch's store (axis_in) and after it (axis_out).
  const T* axis_in = nullptr;
  const T* axis_out = nullptr;
  T band_low = 0, band_high = 0;
  // The way a crossing the event counts moves the coordinate through the band: +1 down (the
  // start not below the band, the end not above it), -1 up, 0 either way.
  int band_way = 0;
};
template <class T>
StateSource<T> with_probe(StateSource<T> in, const FusedJob<T>& job) {
  in.before = job.before, in.probe = job.probe;
  if (in.probe == nullptr || in.probe->count != 1 || !in.probe->tests[0].banded) return in;
  const EventScanJob<T>& plane = in.probe->tests[0];
  in.axis_in = in.x[plane.axis], in.axis_out = job.bodies.x[plane.axis];
  in.band_low = plane.band[0], in.band_high = plane.band[1];
  // A value falling through zero (down) moves the coordinate down where a > 0, up where a < 0.
  const int falls = plane.a[plane.axis] > 0 ? 1 : -1;
  in.band_way = plane.down && plane.up ? 0 : plane.down ? falls : -falls;
  return in;
}
template <class T>
StateSource<T> in_place(const BodyArrays<T>& b) {
  return {{b.x[0], b.x[1], b.x[2]}, {b.v[0], b.v[1], b.v[2]}};
}
template <class T>
StateSource<T> source_of(const FusedJob<T>& job) {
  const T* const* s = job.source;
  return with_probe<T>({{s[0], s[1], s[2]}, {s[3], s[4], s[5]}}, job);
}

// Before a batch's store: its coordinate along a one-plane probe's axis, where there is one.
template <class V>
KINEMA_INLINE V along_before(const StateSource<value_t<V>>& in, std::size_t i) {
  return in.axis_in != nullptr ? load<V>(in.axis_in + i) : V(0);
}

// Whether a body of the batch may have crossed the one-plane probe's plane, from its
// coordinate along the axis before and after the step: outside the band the value's sign is
// known (EventScanJob::band), so a crossing one way needs its start not past the band on one
// side and its end not past it on the other (two compares); either way, both ends on one
// side rule it out. Anything else lets event_scan decide. These kernels are bound by their
// vector instructions: each one here costs about 1% of a step.
template <class V>
KINEMA_INLINE bool near_plane(const StateSource<value_t<V>>& in, V along0, V along1) {
  if (in.band_way == 0) {
    const V above = V(in.band_high) - lane_min(along0, along1), below = lane_max(along0, along1) - V(in.band_low);
    return any_lane(lane_min(above, below) >= V(0));
  }
  if (in.band_way < 0) std::swap(along0, along1);  // up: the end is where a fall would start
  return any_lane((along0 >= V(in.band_low)) & (along1 <= V(in.band_high)));
}

// Lists batch i with the probe; returns where its start state goes: packed, the k-th listed
// batch at k batches from `before` (lines reused every step, so they stay in cache).
template <class V>
KINEMA_INLINE std::size_t listed(EventProbe<value_t<V>>& probe, std::size_t i) {
  const std::size_t k = probe.found++;
  probe.batches[k] = std::uint32_t(i);
  return k * Lane<V>::width;
}

// After a batch's store: the state it started from (x0, v0), where the job asks for it (a
// branch the batches all take the same way); with a probe, only where a body may have crossed
// an event on its way to (x1, v1). along0: along_before's value.
template <class V>
KINEMA_INLINE void keep_before(const StateSource<value_t<V>>& in, std::size_t i, const Vec<V>& x0, const Vec<V>& v0,
                               const Vec<V>& x1, const Vec<V>& v1, const V& along0) {
  if (in.before == nullptr) return;
  std::size_t at = i;
  if (in.axis_in != nullptr) {
    if (!near_plane<V>(in, along0, load<V>(in.axis_out + i))) return;  // a superset of event_scan's exact test
    at = listed<V>(*in.probe, i);
  } else if (in.probe != nullptr) {
    if (!probe_crossed(*in.probe, x0.c, v0.c, x1.c, v1.c)) return;
    at = listed<V>(*in.probe, i);
  }
  for (int d = 0; d < 3; ++d) store(in.before[d] + at, x0.c[d]), store(in.before[3 + d] + at, v0.c[d]);
}

// Asks for the state 1 KiB ahead, once per cache line, and for the source where it is not
// where the state is written: with 13 streams in flight the hardware prefetcher alone
// leaves DRAM latency exposed.
template <class V, class T>
KINEMA_INLINE void prefetch(const BodyArrays<T>& b, const StateSource<T>& in, std::size_t i) {
  constexpr std::size_t ahead = 1024 / sizeof(T), line = 64 / sizeof(T);
  if constexpr (Lane<V>::width < line) {
    if (i % line != 0) return;
  }
  const bool apart = in.x[0] != b.x[0];
  for (int d = 0; d < 3; ++d) {
    __builtin_prefetch(b.x[d] + i + ahead, 1);
    __builtin_prefetch(b.v[d] + i + ahead, 1);
    if (apart) __builtin_prefetch(in.x[d] + i + ahead, 0), __builtin_prefetch(in.v[d] + i + ahead, 0);
  }
  __builtin_prefetch(b.inv_mass + i + ahead, 0);
}

// One batch of a Runge-Kutta step of positions and velocities, the bodies at i, all stages in
// registers. `Pushed`: rigid bodies add the constant force of their point-force terms.
template <const Method& M, bool Quadratic, bool Central, bool Pushed, Applied A, class V>
KINEMA_INLINE void runge_kutta_batch(const BodyArrays<value_t<V>>& b, const StateSource<value_t<V>>& in,
                                     const Forces<V>& f, value_t<V> h, std::size_t i) {
  constexpr ButcherTableau tab = M.tableau;
  constexpr int S = tab.stages;
  constexpr double sigma = acceleration_scale(tab);
  const Vec<V> x = load3<V>(in.x, i), v = load3<V>(in.v, i);
  const auto body = body_terms_at<A, Pushed>(f, load<V>(b.inv_mass + i), b.per_body, i);
  const Vec<V> p = linear_part(body, anchored(f, x));
  Vec<V> kx[S], kv[S];  // stage velocities and accelerations
  static_for<S>([&](auto s) {
    constexpr Weights row = tab.a[s];
    const Vec<V> vs = advanced<row, sigma>(h, kv, v);
    const Vec<V> ps = stage_linear_part<row>(h, body, kx, p);
    // The world position only where a central term needs it.
    const Vec<V> xs = Central ? advanced<row>(h, kx, x) : x;
    kx[s] = vs;
    kv[s] = accel<Quadratic, Central>(f, body, ps, xs, vs);
  });
  const Vec<V> x1 = advanced<tab.b>(h, kx, x), v1 = advanced<tab.b, sigma>(h, kv, v);
  const V along0 = along_before<V>(in, i);
  store3(b.x, i, x1);
  store3(b.v, i, v1);
  keep_before<V>(in, i, x, v, x1, v1, along0);
}

// In place (rigid bodies' centres).
template <const Method& M, bool Quadratic, bool Central, bool Pushed, Applied A, class V>
KINEMA_INLINE void runge_kutta_batch(const BodyArrays<value_t<V>>& b, const Forces<V>& f, value_t<V> h,
                                     std::size_t i) {
  runge_kutta_batch<M, Quadratic, Central, Pushed, A>(b, in_place(b), f, h, i);
}

template <const Method& M, bool Quadratic, int Variant, class V>
KINEMA_INLINE void runge_kutta_loop(const BodyArrays<value_t<V>>& b, const StateSource<value_t<V>>& in,
                                    const Forces<V>& f, value_t<V> h, std::size_t begin, std::size_t end) {
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    prefetch<V>(b, in, i);
    runge_kutta_batch<M, Quadratic, has_central<Variant>, false, reads_applied<Variant>>(b, in, f, h, i);
  }
}

// In place, the loop holds only the set's pointers; from a source, the source's too.
template <const Method& M, bool Quadratic, int Variant, class V>
void fused_runge_kutta(const FusedJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const value_t<V> h = job.h;
  const Forces<V> f(job.forces, value_t<V>(acceleration_scale(M.tableau)) * h);
  const auto b = job.bodies;  // a copy: stores cannot alias it, so pointers stay in registers
  if (job.source == nullptr) {
    return runge_kutta_loop<M, Quadratic, Variant>(b, with_probe(in_place(b), job), f, h, begin, end);
  }
  runge_kutta_loop<M, Quadratic, Variant>(b, source_of(job), f, h, begin, end);
}

template <const Method& M, bool Quadratic, int Variant, class V>
KINEMA_INLINE void kick_drift_loop(const BodyArrays<value_t<V>>& b, const StateSource<value_t<V>>& in,
                                   const Forces<V>& f, value_t<V> h, std::size_t begin, std::size_t end) {
  using T = value_t<V>;
  constexpr bool Central = has_central<Variant>;
  constexpr KickDriftScheme scheme = M.scheme;
  V wh[kMaxStages];
  for (int k = 0; k < scheme.count; ++k) wh[k] = V(T(scheme.ops[k].weight) * h);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> x0 = load3<V>(in.x, i), v0 = load3<V>(in.v, i);
    Vec<V> x = x0, v = v0;
    const auto body = body_terms_at<reads_applied<Variant>>(f, load<V>(b.inv_mass + i), b.per_body, i);
    static_for<scheme.count>([&](auto k) {
      if constexpr (scheme.ops[k].kind == OpKind::kick) {
        v = step_by(wh[k], accel_at<Quadratic, Central>(f, body, x, v), v);
      } else {
        x = step_by(wh[k], v, x);
      }
    });
    const V along0 = along_before<V>(in, i);
    store3(b.x, i, x);
    store3(b.v, i, v);
    keep_before<V>(in, i, x0, v0, x, v, along0);
  }
}

template <const Method& M, bool Quadratic, int Variant, class V>
void fused_kick_drift(const FusedJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const Forces<V> f(job.forces);
  const auto b = job.bodies;  // a copy: stores cannot alias it, so pointers stay in registers
  if (job.source == nullptr) {
    return kick_drift_loop<M, Quadratic, Variant>(b, with_probe(in_place(b), job), f, job.h, begin, end);
  }
  kick_drift_loop<M, Quadratic, Variant>(b, source_of(job), f, job.h, begin, end);
}

template <const Method& M, bool Quadratic, int Variant, class V>
constexpr FusedFn<value_t<V>> fused_kernel() {
  if constexpr (M.kind == MethodKind::runge_kutta) {
    return &fused_runge_kutta<M, Quadratic, Variant, V>;
  } else {
    return &fused_kick_drift<M, Quadratic, Variant, V>;
  }
}

// `advanced` with run-time coefficients, in two parts: the weighted sum of the k, then the
// step from a base. The same operations in the same order.
template <class V>
KINEMA_INLINE Vec<V> group_sum(const Combination<value_t<V>>& c, int g, std::size_t i) {
  const int lead = c.groups.lead[g];
  Vec<V> part = load3<V>(c.k[lead], i);
  for (int j = lead + 1; j < c.terms; ++j) {
    if (c.groups.group[j] != g) continue;
    const Vec<V> k = load3<V>(c.k[j], i);
    for (int d = 0; d < 3; ++d) part.c[d] = part.c[d] + k.c[d];
  }
  return part;
}

template <class V>
KINEMA_INLINE Vec<V> summed(const Combination<value_t<V>>& c, std::size_t i) {
  Vec<V> sum = group_sum<V>(c, 0, i);
  for (int g = 1; g < c.groups.count; ++g) {
    const Vec<V> part = group_sum<V>(c, g, i);
    for (int d = 0; d < 3; ++d) sum.c[d] = accumulate(c.ratio[g], part.c[d], sum.c[d]);
  }
  return sum;
}

template <class V>
KINEMA_INLINE Vec<V> combined(const Combination<value_t<V>>& c, std::size_t i) {
  const Vec<V> base = load3<V>(c.in, i);
  if (c.empty()) return base;
  return stepped(c.step, summed<V>(c, i), base);
}

template <bool Quadratic, bool Central, class V>
void stage(const StageJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const Forces<V> f(job.forces, job.accel_scale);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> x = load3<V>(job.x.in, i);
    const auto body = body_terms_at<Applied::if_present>(f, load<V>(job.inv_mass + i), job.per_body, i);
    Vec<V> xs = x, p = linear_part(body, anchored(f, x));
    const Vec<V> vs = combined<V>(job.v, i);
    if (!job.x.empty()) {
      const Vec<V> sum = summed<V>(job.x, i);
      xs = stepped(job.x.step, sum, x);
      p = linear_part_at(body, job.x.step, sum, p);
      store3(job.x.out, i, xs);
      store3(job.v.out, i, vs);
    }
    store3(job.acc, i, accel<Quadratic, Central>(f, body, p, xs, vs));
  }
}

template <bool Quadratic, bool Central, class V>
void end_accelerations(const EndsJob<value_t<V>>& job) {
  const Forces<V> f(*job.forces, value_t<V>(1));
  const auto body = body_terms_at<Applied::if_present>(f, load<V>(job.inv_mass), job.per_body, 0);
  for (int e = 0; e < 2; ++e) {
    const Vec<V> x = load3<V>(job.x[e], 0), v = load3<V>(job.v[e], 0);
    store3(job.acc[e], 0, accel<Quadratic, Central>(f, body, linear_part(body, anchored(f, x)), x, v));
  }
}

template <class V>
void combine(const CombineJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    store3(job.c.out, i, combined<V>(job.c, i));
  }
}

template <class V>
void add_forces(const ForceJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const V inv_mass = load<V>(job.inv_mass + i), scale(job.scale);
    const Vec<V> a = load3<V>(job.acc, i), force = load3<V>(job.force, i);
    Vec<V> sum;
    for (int d = 0; d < 3; ++d) {
      sum.c[d] = pick(inv_mass != V(0), mul_add(inv_mass, scale * force.c[d], a.c[d]), a.c[d]);
    }
    store3(job.acc, i, sum);
  }
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
