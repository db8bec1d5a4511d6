#pragma once
// The particle block path's kernels (see BlockJob): what the fused kernels do for one stage
// at a time, so that callbacks can run between the stages of a slice of bodies.

#include "kernels/kernel_impl.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

// Stage S's state x + h sum_j a_Sj kx_j, v + sum_j (a_Sj / sigma) kv_j, formed as the fused
// kernels form it; the callbacks' forces zeroed.
template <const Method& M, int S, class V>
KINEMA_INLINE void block_stage_at(const BlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  constexpr ButcherTableau tab = M.tableau;
  constexpr Weights row = tab.a[S];
  constexpr double sigma = acceleration_scale(tab);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    store3(job.force, i, Vec<V>{{V(0), V(0), V(0)}});
    if constexpr (S > 0) {
      Vec<V> kx[tab.stages] = {}, kv[tab.stages] = {};
      static_for<S>([&](auto j) {
        if constexpr (row[j] != 0) kx[j] = load3<V>(job.vs[j], i), kv[j] = load3<V>(job.kv[j], i);
      });
      store3(job.xs[S], i, advanced<row>(job.h, kx, load3<V>(job.bodies.x, i)));
      store3(job.vs[S], i, advanced<row, sigma>(job.h, kv, load3<V>(job.bodies.v, i)));
    }
  }
}

template <const Method& M, class V>
void block_stage(const BlockJob<value_t<V>>& job, int stage, std::size_t begin, std::size_t end) {
  static_for<M.tableau.stages>([&](auto s) {
    if (s == stage) block_stage_at<M, s, V>(job, begin, end);
  });
}

// The accelerations at a stage's state, with the callbacks' forces and the applied ones:
// kv = accel_scale (local terms + inv_mass F).
template <bool Quadratic, bool Central, class V>
void block_rates(const BlockJob<value_t<V>>& job, int s, std::size_t begin, std::size_t end) {
  const Forces<V> f(job.forces, job.accel_scale);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const V inv_mass = load<V>(job.bodies.inv_mass + i);
    auto body = body_terms_at<Applied::if_present>(f, inv_mass, job.bodies.applied, i);
    add_applied(body, f, inv_mass, load3<V>(job.force, i));
    store3(job.kv[s], i, accel_at<Quadratic, Central>(f, body, load3<V>(job.xs[s], i), load3<V>(job.vs[s], i)));
  }
}

// x + h sum_j b_j kx_j and v + sum_j (b_j / sigma) kv_j, as the fused kernels finish a step.
template <const Method& M, class V>
void block_finish(const BlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  constexpr ButcherTableau tab = M.tableau;
  constexpr double sigma = acceleration_scale(tab);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    Vec<V> kx[tab.stages] = {}, kv[tab.stages] = {};
    static_for<tab.stages>([&](auto j) {
      if constexpr (tab.b[j] != 0) kx[j] = load3<V>(job.vs[j], i), kv[j] = load3<V>(job.kv[j], i);
    });
    const Vec<V> x = load3<V>(job.bodies.x, i), v = load3<V>(job.bodies.v, i);
    store3(job.bodies.x, i, advanced<tab.b>(job.h, kx, x));
    store3(job.bodies.v, i, advanced<tab.b, sigma>(job.h, kv, v));
  }
}

// A kick: v + step (local accelerations + inv_mass F) at the bodies' state.
template <bool Quadratic, bool Central, class V>
void block_kick(const BlockJob<value_t<V>>& job, value_t<V> step, std::size_t begin, std::size_t end) {
  const Forces<V> f(job.forces);
  const V wh(step);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const V inv_mass = load<V>(job.bodies.inv_mass + i);
    auto body = body_terms_at<Applied::if_present>(f, inv_mass, job.bodies.applied, i);
    add_applied(body, f, inv_mass, load3<V>(job.force, i));
    const Vec<V> x = load3<V>(job.bodies.x, i), v = load3<V>(job.bodies.v, i);
    store3(job.bodies.v, i, step_by(wh, accel_at<Quadratic, Central>(f, body, x, v), v));
  }
}

// A drift: x + step v.
template <class V>
void block_drift(const BlockJob<value_t<V>>& job, value_t<V> step, std::size_t begin, std::size_t end) {
  const V wh(step);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    store3(job.bodies.x, i, step_by(wh, load3<V>(job.bodies.v, i), load3<V>(job.bodies.x, i)));
  }
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
