#pragma once
// The kernels, written once over a lane type V (a scalar T or an xsimd batch) and
// instantiated per instruction set by kernels_<isa>.cpp, each inside its own namespace.

#include <array>
#include <cstddef>
#include <utility>

#include "kernels/kernels.hpp"
#include "kernels/wide.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

template <int N, class F>
inline void static_for(F&& f) {
  [&]<int... I>(std::integer_sequence<int, I...>) {
    (f(std::integral_constant<int, I>{}), ...);
  }(std::make_integer_sequence<int, N>{});
}

template <class V>
struct Vec {
  V c[3];
};

template <class V>
inline Vec<V> load3(const value_t<V>* const p[3], std::size_t i) {
  return {{load<V>(p[0] + i), load<V>(p[1] + i), load<V>(p[2] + i)}};
}
template <class V>
inline void store3(value_t<V>* const p[3], std::size_t i, const Vec<V>& v) {
  for (int d = 0; d < 3; ++d) store(p[d] + i, v.c[d]);
}

// The local force terms, broadcast to lanes once per call.
template <class V>
struct Forces {
  using T = value_t<V>;
  V g[3], anchor[3], neg_spring_k, neg_linear, neg_quadratic;
  int central_count;
  V center[4][3], neg_mu[4];

  explicit Forces(const LocalForces<T>& f)
      : neg_spring_k(-f.spring_k), neg_linear(-f.linear), neg_quadratic(-f.quadratic),
        central_count(f.central_count) {
    for (int d = 0; d < 3; ++d) {
      g[d] = V(f.gravity[d]);
      anchor[d] = V(f.anchor[d]);
    }
    for (int c = 0; c < central_count; ++c) {
      for (int d = 0; d < 3; ++d) center[c][d] = V(f.center[c][d]);
      neg_mu[c] = V(-f.mu[c]);
    }
  }
};

// Acceleration of bodies at (x, v): the sum of the local terms, zero where inv_mass is 0.
// The operation order is part of the contract: every path and both step paths use this.
template <bool Quadratic, bool Central, class V, class M>
inline Vec<V> accel(const Forces<V>& f, const Vec<V>& x, const Vec<V>& v, const V& inv_mass,
                    const M& dynamic) {
  // Velocity-proportional coefficient: linear drag and spring damping, plus k |v|.
  V neg_drag = f.neg_linear;
  if constexpr (Quadratic) {
    V speed = root(fused(v.c[0], v.c[0], fused(v.c[1], v.c[1], v.c[2] * v.c[2])));
    neg_drag = fused(f.neg_quadratic, speed, neg_drag);
  }
  Vec<V> a;
  for (int d = 0; d < 3; ++d) {
    V force = fused(f.neg_spring_k, x.c[d] - f.anchor[d], neg_drag * v.c[d]);
    a.c[d] = fused(inv_mass, force, f.g[d]);
  }
  if constexpr (Central) {
    for (int c = 0; c < f.central_count; ++c) {
      Vec<V> r;
      for (int d = 0; d < 3; ++d) r.c[d] = x.c[d] - f.center[c][d];
      V r2 = fused(r.c[0], r.c[0], fused(r.c[1], r.c[1], r.c[2] * r.c[2]));
      V scale = f.neg_mu[c] / (r2 * root(r2));  // -mu / |r|^3
      for (int d = 0; d < 3; ++d) a.c[d] = fused(scale, r.c[d], a.c[d]);
    }
  }
  for (int d = 0; d < 3; ++d) a.c[d] = pick(dynamic, a.c[d], V(0));
  return a;
}

template <class V>
inline Vec<V> step_by(const V& h, const Vec<V>& dir, const Vec<V>& base) {
  return {{fused(h, dir.c[0], base.c[0]), fused(h, dir.c[1], base.c[1]),
           fused(h, dir.c[2], base.c[2])}};
}

using Weights = std::array<double, kMaxStages>;

constexpr int first_nonzero(const Weights& w) {
  for (int j = 0; j < kMaxStages; ++j) {
    if (w[j] != 0) return j;
  }
  return -1;
}

// base + h * sum_j w_j k_j, the sum formed as w_first k_first then fused multiply-adds in
// j order over the nonzero weights. The staged path's `combined` does the same at run time.
template <Weights W, class V, int N>
inline Vec<V> advanced(const V& h, const Vec<V> (&k)[N], const Vec<V>& base) {
  using T = value_t<V>;
  constexpr int first = first_nonzero(W);
  if constexpr (first < 0) {
    return base;
  } else {
    Vec<V> sum;
    static_for<N>([&](auto j) {
      if constexpr (j == first) {
        for (int d = 0; d < 3; ++d) sum.c[d] = V(T(W[j])) * k[j].c[d];
      } else if constexpr (j > first && W[j] != 0) {
        for (int d = 0; d < 3; ++d) sum.c[d] = fused(V(T(W[j])), k[j].c[d], sum.c[d]);
      }
    });
    return step_by(h, sum, base);
  }
}


template <const Method& M, bool Quadratic, bool Central, class V>
void fused_runge_kutta(const FusedJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  constexpr ButcherTableau tab = M.tableau;
  constexpr int S = tab.stages;
  const Forces<V> f(job.forces);
  const V h(job.h);
  const auto& b = job.bodies;
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> x = load3<V>(b.x, i), v = load3<V>(b.v, i);
    const V inv_mass = load<V>(b.inv_mass + i);
    const auto dynamic = inv_mass != V(0);
    Vec<V> kx[S], kv[S];  // stage velocities and accelerations
    static_for<S>([&](auto s) {
      constexpr Weights row = tab.a[s];
      const Vec<V> xs = advanced<row>(h, kx, x), vs = advanced<row>(h, kv, v);
      kx[s] = vs;
      kv[s] = accel<Quadratic, Central>(f, xs, vs, inv_mass, dynamic);
    });
    store3(b.x, i, advanced<tab.b>(h, kx, x));
    store3(b.v, i, advanced<tab.b>(h, kv, v));
  }
}

template <const Method& M, bool Quadratic, bool Central, class V>
void fused_kick_drift(const FusedJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  using T = value_t<V>;
  constexpr KickDriftScheme scheme = M.scheme;
  const Forces<V> f(job.forces);
  const auto& b = job.bodies;
  V wh[kMaxStages];
  for (int k = 0; k < scheme.count; ++k) wh[k] = V(T(scheme.ops[k].weight) * job.h);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    Vec<V> x = load3<V>(b.x, i), v = load3<V>(b.v, i);
    const V inv_mass = load<V>(b.inv_mass + i);
    const auto dynamic = inv_mass != V(0);
    static_for<scheme.count>([&](auto k) {
      if constexpr (scheme.ops[k].kind == OpKind::kick) {
        v = step_by(wh[k], accel<Quadratic, Central>(f, x, v, inv_mass, dynamic), v);
      } else {
        x = step_by(wh[k], v, x);
      }
    });
    store3(b.x, i, x);
    store3(b.v, i, v);
  }
}

template <const Method& M, bool Quadratic, bool Central, class V>
constexpr FusedFn<value_t<V>> fused_kernel() {
  if constexpr (M.kind == MethodKind::runge_kutta) {
    return &fused_runge_kutta<M, Quadratic, Central, V>;
  } else {
    return &fused_kick_drift<M, Quadratic, Central, V>;
  }
}

// in + h * sum_j coef_j k_j with run-time coefficients, same operation order as above.
template <class V>
inline Vec<V> combined(const Combination<value_t<V>>& c, const V& h, std::size_t i) {
  const Vec<V> base = load3<V>(c.in, i);
  if (c.terms == 0) return base;
  Vec<V> sum = load3<V>(c.k[0], i);
  for (int d = 0; d < 3; ++d) sum.c[d] = V(c.coef[0]) * sum.c[d];
  for (int j = 1; j < c.terms; ++j) {
    const Vec<V> k = load3<V>(c.k[j], i);
    for (int d = 0; d < 3; ++d) sum.c[d] = fused(V(c.coef[j]), k.c[d], sum.c[d]);
  }
  return step_by(h, sum, base);
}

template <bool Quadratic, bool Central, class V>
void stage(const StageJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const Forces<V> f(job.forces);
  const V h(job.h);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> xs = combined<V>(job.x, h, i), vs = combined<V>(job.v, h, i);
    if (job.x.terms > 0) {
      store3(job.x.out, i, xs);
      store3(job.v.out, i, vs);
    }
    const V inv_mass = load<V>(job.inv_mass + i);
    store3(job.acc, i, accel<Quadratic, Central>(f, xs, vs, inv_mass, inv_mass != V(0)));
  }
}

template <class V>
void combine(const CombineJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const V h(job.h);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    store3(job.c.out, i, combined<V>(job.c, h, i));
  }
}

template <class V>
void add_forces(const ForceJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const V inv_mass = load<V>(job.inv_mass + i);
    const Vec<V> a = load3<V>(job.acc, i), force = load3<V>(job.force, i);
    Vec<V> sum;
    for (int d = 0; d < 3; ++d) {
      sum.c[d] = pick(inv_mass != V(0), fused(inv_mass, force.c[d], a.c[d]), a.c[d]);
    }
    store3(job.acc, i, sum);
  }
}

template <class V>
KernelTable<value_t<V>> make_table(Isa isa) {
  KernelTable<value_t<V>> t{};
  t.isa = isa;
  t.width = Lane<V>::width;
  static_for<int(kBuiltinCount)>([&](auto m) {
    constexpr const Method& method = *builtin_methods[m];
    t.fused[m][0][0] = fused_kernel<method, false, false, V>();
    t.fused[m][0][1] = fused_kernel<method, false, true, V>();
    t.fused[m][1][0] = fused_kernel<method, true, false, V>();
    t.fused[m][1][1] = fused_kernel<method, true, true, V>();
  });
  t.stage[0][0] = &stage<false, false, V>;
  t.stage[0][1] = &stage<false, true, V>;
  t.stage[1][0] = &stage<true, false, V>;
  t.stage[1][1] = &stage<true, true, V>;
  t.combine = &combine<V>;
  t.add_forces = &add_forces<V>;
  return t;
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
