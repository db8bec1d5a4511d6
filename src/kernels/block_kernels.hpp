#pragma once
// The particle block path's kernels (see BlockJob): what the fused kernels do, one stage at a
// time, so that callbacks can run between the stages of a slice of bodies. Each kernel runs
// over one slice: the bodies' arrays from the slice's first body, its stage state in the
// slice's scratch.

#include "kernels/kernel_impl.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

// Pointers to one slice's arrays. With the layout a compile-time constant, every scratch
// array is the scratch pointer and a constant offset.
template <class T, SliceLayout L>
struct SliceArrays {
  const BlockJob<T>& job;
  T* scratch;
  std::size_t begin;

  T* at(std::size_t array) const { return scratch + array * kSliceBodies<T>; }
  // Stage s's positions and velocities (stage 0: the bodies').
  void stage(T* x[3], T* v[3], int s) const {
    for (int d = 0; d < 3; ++d) {
      x[d] = s > 0 ? at(L.xs(s, d)) : job.bodies.x[d] + begin;
      v[d] = s > 0 ? at(L.vs(s, d)) : job.bodies.v[d] + begin;
    }
  }
  void rates(T* kv[3], int s) const {
    for (int d = 0; d < 3; ++d) kv[d] = at(L.kv(s, d));
  }
  void forces(T* f[3]) const {
    for (int d = 0; d < 3; ++d) f[d] = at(L.force(d));
  }
  const T* inv_mass() const { return job.bodies.inv_mass + begin; }
  PerBody<T> per_body() const { return job.bodies.per_body.from(begin); }
};

// The callbacks' forces joined to the local terms and applied forces: accel_scale times the
// acceleration at (x, v).
template <bool Quadratic, bool Central, class V>
KINEMA_INLINE Vec<V> callback_rates(const Forces<V>& f, const value_t<V>* inv_mass, const PerBody<value_t<V>>& own,
                                    const value_t<V>* const force[3], std::size_t i, const Vec<V>& x, const Vec<V>& v) {
  const V m = load<V>(inv_mass + i);
  auto body = body_terms_at<Applied::if_present>(f, m, own, i);
  add_applied(body, f, m, load3<V>(force, i));
  return accel_at<Quadratic, Central>(f, body, x, v);
}

// Stage S's rates from its state and what the callbacks added (zeroed after they are read:
// the next stage's callbacks add to zero); then the state of stage S + 1, or after the last
// stage the step's end x + h sum_j b_j kx_j, v + sum_j (b_j / sigma) kv_j. The same
// arithmetic as the fused kernels; a stage's rates are kept only where a later stage or the
// end reads them.
template <const Method& M, int S, bool Quadratic, bool Central, class V>
KINEMA_INLINE void block_advance_at(const BlockJob<value_t<V>>& job, value_t<V>* scratch, std::size_t begin,
                                    std::size_t count) {
  using T = value_t<V>;
  constexpr ButcherTableau tab = M.tableau;
  constexpr bool last = S + 1 == tab.stages;
  constexpr Weights row = last ? tab.b : tab.a[S + 1];
  constexpr double sigma = acceleration_scale(tab);
  const SliceArrays<T, SliceLayout{tab.stages}> a{job, scratch, begin};
  const Forces<V> f(job.forces, job.accel_scale);
  const T h = job.h;  // a local: the stores below may not change it
  T *x0[3], *v0[3], *xs[3], *vs[3], *force[3], *next_x[3], *next_v[3];
  T *kx[tab.stages][3], *kv[tab.stages][3];
  const PerBody<T> own = a.per_body();
  const T* inv_mass = a.inv_mass();
  a.stage(x0, v0, 0), a.stage(xs, vs, S), a.forces(force);
  if constexpr (!last) a.stage(next_x, next_v, S + 1);
  static_for<S>([&](auto j) {
    T* unused[3];
    a.stage(unused, kx[j], j), a.rates(kv[j], j);
  });
  a.rates(kv[S], S);
  // Whether a later stage or the step's end reads stage S's rates from memory.
  constexpr bool kept = [] {
    bool read = !last && M.tableau.b[S] != 0;
    for (int t = S + 2; t < M.tableau.stages; ++t) read = read || M.tableau.a[t][S] != 0;
    return read;
  }();
  for (std::size_t i = 0; i < count; i += Lane<V>::width) {
    const Vec<V> x = load3<V>(xs, i), v = load3<V>(vs, i);
    const Vec<V> accel = callback_rates<Quadratic, Central>(f, inv_mass, own, force, i, x, v);
    Vec<V> kxs[tab.stages] = {}, kvs[tab.stages] = {};
    static_for<S + 1>([&](auto j) {
      if constexpr (row[j] == 0) return;
      if constexpr (j == S) {
        kxs[j] = v, kvs[j] = accel;
      } else {
        kxs[j] = load3<V>(kx[j], i), kvs[j] = load3<V>(kv[j], i);
      }
    });
    const Vec<V> start_x = load3<V>(x0, i), start_v = load3<V>(v0, i);
    store3(force, i, Vec<V>{{V(0), V(0), V(0)}});
    if constexpr (last) {
      store3(x0, i, advanced<row>(h, kxs, start_x));
      store3(v0, i, advanced<row, sigma>(h, kvs, start_v));
    } else {
      if constexpr (kept) store3(kv[S], i, accel);
      store3(next_x, i, advanced<row>(h, kxs, start_x));
      store3(next_v, i, advanced<row, sigma>(h, kvs, start_v));
    }
  }
}

template <const Method& M, bool Quadratic, bool Central, class V>
void block_advance(const BlockJob<value_t<V>>& job, value_t<V>* scratch, int stage, std::size_t begin,
                   std::size_t count) {
  static_for<M.tableau.stages>([&](auto s) {
    if (s == stage) block_advance_at<M, s, Quadratic, Central, V>(job, scratch, begin, count);
  });
}

// A kick: v + step (local accelerations + inv_mass F) at the bodies' state; F zeroed.
template <bool Quadratic, bool Central, class V>
void block_kick(const BlockJob<value_t<V>>& job, value_t<V>* scratch, value_t<V> step, std::size_t begin,
                std::size_t count) {
  using T = value_t<V>;
  const SliceArrays<T, SliceLayout{1}> a{job, scratch, begin};
  const Forces<V> f(job.forces);
  const V wh(step);
  T *x[3], *v[3], *force[3];
  const PerBody<T> own = a.per_body();
  const T* inv_mass = a.inv_mass();
  a.stage(x, v, 0), a.forces(force);
  for (std::size_t i = 0; i < count; i += Lane<V>::width) {
    const Vec<V> xi = load3<V>(x, i), vi = load3<V>(v, i);
    const Vec<V> accel = callback_rates<Quadratic, Central>(f, inv_mass, own, force, i, xi, vi);
    store3(force, i, Vec<V>{{V(0), V(0), V(0)}});
    store3(v, i, step_by(wh, accel, vi));
  }
}

// A drift: x + step v.
template <class V>
void block_drift(const BlockJob<value_t<V>>& job, value_t<V>* scratch, value_t<V> step, std::size_t begin,
                 std::size_t count) {
  using T = value_t<V>;
  const SliceArrays<T, SliceLayout{1}> a{job, scratch, begin};
  const V wh(step);
  T *x[3], *v[3];
  a.stage(x, v, 0);
  for (std::size_t i = 0; i < count; i += Lane<V>::width) store3(x, i, step_by(wh, load3<V>(v, i), load3<V>(x, i)));
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
