#pragma once
// Rigid-body kernels: the particle kernels' translation plus orientation q and world
// angular momentum L, integrated together in registers.
//   omega = R diag(1/I) R^T L,  dq/dt = 1/2 (0, omega) * q,  dL/dt = torque.
// R is the rotation of q / |q|, so stage quaternions that drift off unit length still give
// a true rotation; q is renormalized after each step.

#include <cassert>

#include "kernels/kernel_impl.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

template <class V>
using Quat4 = Vec<V, 4>;

template <class V>
struct Rotation {
  V m[3][3];
};

// Rotation matrix of q / |q|: with s = 2 / |q|^2, R = I + s (w [u]x + [u]x^2), u = (x, y, z).
template <class V>
KINEMA_INLINE Rotation<V> rotation(const Quat4<V>& q) {
  const V w = q.c[0], x = q.c[1], y = q.c[2], z = q.c[3];
  const V s = V(2) / mul_add(w, w, mul_add(x, x, mul_add(y, y, z * z)));
  const V xs = x * s, ys = y * s, zs = z * s;
  const V wx = w * xs, wy = w * ys, wz = w * zs, xx = x * xs, xy = x * ys, xz = x * zs;
  const V yy = y * ys, yz = y * zs, zz = z * zs, one(1);
  return {{{one - (yy + zz), xy - wz, xz + wy},
           {xy + wz, one - (xx + zz), yz - wx},
           {xz - wy, yz + wx, one - (xx + yy)}}};
}

template <class V>
KINEMA_INLINE Vec<V> times(const Rotation<V>& r, const Vec<V>& v) {
  Vec<V> out;
  for (int d = 0; d < 3; ++d) {
    out.c[d] = mul_add(r.m[d][0], v.c[0], mul_add(r.m[d][1], v.c[1], r.m[d][2] * v.c[2]));
  }
  return out;
}

template <class V>
KINEMA_INLINE Vec<V> transposed_times(const Rotation<V>& r, const Vec<V>& v) {
  Vec<V> out;
  for (int d = 0; d < 3; ++d) {
    out.c[d] = mul_add(r.m[0][d], v.c[0], mul_add(r.m[1][d], v.c[1], r.m[2][d] * v.c[2]));
  }
  return out;
}

template <class V>
KINEMA_INLINE Vec<V> cross(const Vec<V>& a, const Vec<V>& b) {
  return {{mul_add(a.c[1], b.c[2], -(a.c[2] * b.c[1])), mul_add(a.c[2], b.c[0], -(a.c[0] * b.c[2])),
           mul_add(a.c[0], b.c[1], -(a.c[1] * b.c[0]))}};
}

// omega = R diag(1/I) R^T L
template <class V>
KINEMA_INLINE Vec<V> angular_velocity(const Rotation<V>& r, const Vec<V>& inv_inertia, const Vec<V>& l) {
  Vec<V> body = transposed_times(r, l);
  for (int d = 0; d < 3; ++d) body.c[d] = body.c[d] * inv_inertia.c[d];
  return times(r, body);
}

// dq/dt = 1/2 (0, omega) * q = 1/2 (-omega . u, w omega + omega x u)
template <class V>
KINEMA_INLINE Quat4<V> quaternion_rate(const Vec<V>& omega, const Quat4<V>& q) {
  const V half(0.5);
  Vec<V> o;
  for (int d = 0; d < 3; ++d) o.c[d] = half * omega.c[d];  // exact
  const Vec<V> u{{q.c[1], q.c[2], q.c[3]}};
  const Vec<V> ou = cross(o, u);
  return {{-mul_add(o.c[0], u.c[0], mul_add(o.c[1], u.c[1], o.c[2] * u.c[2])),
           mul_add(q.c[0], o.c[0], ou.c[0]), mul_add(q.c[0], o.c[1], ou.c[1]),
           mul_add(q.c[0], o.c[2], ou.c[2])}};
}

template <class V>
struct Rotational {
  V torque[3], neg_drag;
  int point_count;
  Vec<V> point[4], force[4];

  explicit Rotational(const RotationalForces<value_t<V>>& r)
      : neg_drag(-r.angular_drag), point_count(r.point_count) {
    for (int d = 0; d < 3; ++d) torque[d] = V(r.torque[d]);
    for (int p = 0; p < point_count; ++p) {
      for (int d = 0; d < 3; ++d) point[p].c[d] = V(r.point[p][d]), force[p].c[d] = V(r.force[p][d]);
    }
  }
};

// torque = T0 - c omega + sum (R p) x F (+ the body's applied torque, when `applied`), zero
// where inv_mass is 0.
template <class V, class B>
KINEMA_INLINE Vec<V> torque(const Rotational<V>& f, const B& body, const Rotation<V>& r,
                     const Vec<V>& omega, const Vec<V>* applied = nullptr) {
  Vec<V> t;
  for (int d = 0; d < 3; ++d) t.c[d] = mul_add(f.neg_drag, omega.c[d], f.torque[d]);
  for (int p = 0; p < f.point_count; ++p) {
    const Vec<V> arm = cross(times(r, f.point[p]), f.force[p]);
    for (int d = 0; d < 3; ++d) t.c[d] = t.c[d] + arm.c[d];
  }
  if (applied != nullptr) {
    for (int d = 0; d < 3; ++d) t.c[d] = t.c[d] + applied->c[d];
  }
  for (int d = 0; d < 3; ++d) t.c[d] = pick(body.dynamic, t.c[d], V(0));
  return t;
}

// The body's angular damping, where its set has it: tau - c L, zero where inv_mass is 0.
template <class V, class B>
KINEMA_INLINE Vec<V> damped(const Vec<V>& tau, const B& body, const V* neg_rate, const Vec<V>& l) {
  if (neg_rate == nullptr) return tau;
  Vec<V> t;
  for (int d = 0; d < 3; ++d) t.c[d] = pick(body.dynamic, mul_add(*neg_rate, l.c[d], tau.c[d]), V(0));
  return t;
}

// -c per body at i, or nullptr when the set has no angular damping.
template <class V>
KINEMA_INLINE const V* neg_damping_at(const value_t<V>* rates, std::size_t i, V& storage) {
  if (rates == nullptr) return nullptr;
  storage = V(0) - load<V>(rates + i);
  return &storage;
}

// The bodies' applied torques at i, or nullptr when the set has none.
template <class V>
KINEMA_INLINE const Vec<V>* applied_torque_at(const value_t<V>* const torques[3], std::size_t i, Vec<V>& storage) {
  if (torques[0] == nullptr) return nullptr;
  storage = load3<V>(torques, i);
  return &storage;
}
template <class V>
KINEMA_INLINE const Vec<V>* applied_torque(const RigidJob<value_t<V>>& job, std::size_t i, Vec<V>& storage) {
  return applied_torque_at<V>(job.torque, i, storage);
}

template <class V>
struct RigidState {
  Vec<V> x, v;
  Quat4<V> q;
  Vec<V> l;
};

template <class V>
KINEMA_INLINE Quat4<V> normalized(const Quat4<V>& q) {
  const V norm = root(mul_add(q.c[0], q.c[0], mul_add(q.c[1], q.c[1], mul_add(q.c[2], q.c[2], q.c[3] * q.c[3]))));
  Quat4<V> out;
  for (int k = 0; k < 4; ++k) out.c[k] = q.c[k] / norm;
  return out;
}

template <class V>
KINEMA_INLINE RigidState<V> load_rigid(const RigidJob<value_t<V>>& job, std::size_t i) {
  return {load3<V>(job.bodies.x, i), load3<V>(job.bodies.v, i), load_n<4, V>(job.q, i),
          load3<V>(job.l, i)};
}

template <class V>
KINEMA_INLINE void store_rigid(const RigidJob<value_t<V>>& job, std::size_t i, RigidState<V> s) {
  if (job.renormalize) s.q = normalized(s.q);
  store3(job.bodies.x, i, s.x);
  store3(job.bodies.v, i, s.v);
  store_n<4, V>(job.q, i, s.q);
  store3(job.l, i, s.l);
}

// A rigid step is two independent problems sharing inv_mass: the centre's x and v, and the
// orientation's q and L (the force of point terms is constant; only the torque turns with q).
// The kernel takes them in two passes over the range. The translation is the particle step's
// batch (runge_kutta_batch, with the point forces' push).
// The rotation is a long chain of dependent operations per stage (|q|^2, a division, R^T L,
// R again, the quaternion rate); two batches go through each stage together so that the core
// overlaps their chains. Each value sees the same operations in the same order either way.
template <class M>
struct Dynamic {
  M dynamic;  // what torque() reads of a body
};

template <const Method& M, int U, bool Applied, class V>
KINEMA_INLINE void rigid_rotation(const RigidJob<value_t<V>>& job, const Rotational<V>& rf, std::size_t i) {
  constexpr ButcherTableau tab = M.tableau;
  constexpr int S = tab.stages;
  constexpr std::size_t W = Lane<V>::width;
  const value_t<V> h = job.h;
  using Mask = std::decay_t<decltype(load<V>(job.bodies.inv_mass) != V(0))>;
  Quat4<V> q0[U], kq[U][S];
  Vec<V> l0[U], inv_inertia[U], kl[U][S], applied_storage[U];
  const Vec<V>* applied[U];
  V damping_storage[U];
  const V* neg_damping[U];
  Dynamic<Mask> body[U];
  for (int u = 0; u < U; ++u) {
    q0[u] = load_n<4, V>(job.q, i + u * W);
    l0[u] = load3<V>(job.l, i + u * W);
    inv_inertia[u] = load3<V>(job.inv_inertia, i + u * W);
    body[u].dynamic = load<V>(job.bodies.inv_mass + i + u * W) != V(0);
    applied[u] = Applied ? applied_torque<V>(job, i + u * W, applied_storage[u]) : nullptr;
    neg_damping[u] = Applied ? neg_damping_at<V>(job.angular_damping, i + u * W, damping_storage[u]) : nullptr;
  }
  static_for<S>([&](auto s) {
    constexpr Weights row = tab.a[s];
    for (int u = 0; u < U; ++u) {
      const Quat4<V> qs = advanced<row>(h, kq[u], q0[u]);
      const Vec<V> ls = advanced<row>(h, kl[u], l0[u]);
      const Rotation<V> r = rotation(qs);
      const Vec<V> omega = angular_velocity(r, inv_inertia[u], ls);
      kq[u][s] = quaternion_rate(omega, qs);
      kl[u][s] = damped(torque(rf, body[u], r, omega, applied[u]), body[u], neg_damping[u], ls);
    }
  });
  for (int u = 0; u < U; ++u) {
    const Quat4<V> q = advanced<tab.b>(h, kq[u], q0[u]);
    store_n<4, V>(job.q, i + u * W, job.renormalize ? normalized(q) : q);
    store3(job.l, i + u * W, advanced<tab.b>(h, kl[u], l0[u]));
  }
}

// The rotation of bodies [begin, end), with or without applied torques: one function per
// method, shared by the kernel's variants (it does not depend on the centre's terms).
template <const Method& M, bool Applied, class V>
void rotation_pass(const RigidJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  constexpr std::size_t W = Lane<V>::width;
  const Rotational<V> rf(job.rotation);
  std::size_t i = begin;
  for (; i + 2 * W <= end; i += 2 * W) rigid_rotation<M, 2, Applied>(job, rf, i);
  if (i < end) rigid_rotation<M, 1, Applied>(job, rf, i);
}

template <const Method& M, bool Quadratic, bool Central, class V>
void rigid_runge_kutta(const RigidJob<value_t<V>>& shared, std::size_t begin, std::size_t end) {
  const RigidJob<value_t<V>> job = shared;  // a copy: stores cannot alias its pointers
  constexpr double sigma = acceleration_scale(M.tableau);
  const Forces<V> f(job.forces, value_t<V>(sigma) * job.h);
  constexpr std::size_t W = Lane<V>::width;
  if (job.bodies.per_body.any()) {
    for (std::size_t i = begin; i < end; i += W) runge_kutta_batch<M, Quadratic, Central, true, Applied::if_present>(job.bodies, f, job.h, i);
  } else {
    for (std::size_t i = begin; i < end; i += W) runge_kutta_batch<M, Quadratic, Central, true, Applied::never>(job.bodies, f, job.h, i);
  }
  if (job.torque[0] != nullptr || job.angular_damping != nullptr) return rotation_pass<M, true, V>(job, begin, end);
  rotation_pass<M, false, V>(job, begin, end);
}

// Kick-drift for rigid bodies: a kick updates v and L; a drift moves x and turns q with the
// current L, by Euler for first-order schemes and by the midpoint rule for second-order
// ones, so the rotation keeps the scheme's order.
template <const Method& M, bool Quadratic, bool Central, class V>
void rigid_kick_drift(const RigidJob<value_t<V>>& shared, std::size_t begin, std::size_t end) {
  const RigidJob<value_t<V>> job = shared;  // a copy: stores cannot alias its pointers
  using T = value_t<V>;
  constexpr KickDriftScheme scheme = M.scheme;
  const Forces<V> f(job.forces);
  const Rotational<V> rf(job.rotation);
  V wh[kMaxStages], half_wh[kMaxStages];
  for (int k = 0; k < scheme.count; ++k) {
    wh[k] = V(T(scheme.ops[k].weight) * job.h);
    half_wh[k] = V(T(0.5 * scheme.ops[k].weight) * job.h);
  }
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    RigidState<V> s = load_rigid<V>(job, i);
    const auto body = body_terms_at<Applied::if_present, true>(f, load<V>(job.bodies.inv_mass + i), job.bodies.per_body, i);
    const Vec<V> inv_inertia = load3<V>(job.inv_inertia, i);
    Vec<V> applied_storage;
    const Vec<V>* applied = applied_torque<V>(job, i, applied_storage);
    V damping_storage;
    const V* neg_damping = neg_damping_at<V>(job.angular_damping, i, damping_storage);
    auto rate = [&](const Quat4<V>& q) {
      return quaternion_rate(angular_velocity(rotation(q), inv_inertia, s.l), q);
    };
    static_for<scheme.count>([&](auto k) {
      if constexpr (scheme.ops[k].kind == OpKind::kick) {
        const Rotation<V> r = rotation(s.q);
        const Vec<V> omega = angular_velocity(r, inv_inertia, s.l);
        const Vec<V> tau = damped(torque(rf, body, r, omega, applied), body, neg_damping, s.l);
        s.v = step_by(wh[k], accel_at<Quadratic, Central>(f, body, s.x, s.v), s.v);
        s.l = step_by(wh[k], tau, s.l);
      } else {
        s.x = step_by(wh[k], s.v, s.x);
        if constexpr (M.order >= 2) {
          s.q = step_by(wh[k], rate(step_by(half_wh[k], rate(s.q), s.q)), s.q);
        } else {
          s.q = step_by(wh[k], rate(s.q), s.q);
        }
      }
    });
    store_rigid<V>(job, i, s);
  }
}

template <const Method& M, bool Quadratic, bool Central, class V>
constexpr RigidFn<value_t<V>> rigid_kernel() {
  if constexpr (M.kind == MethodKind::runge_kutta) {
    return &rigid_runge_kutta<M, Quadratic, Central, V>;
  } else {
    return &rigid_kick_drift<M, Quadratic, Central, V>;
  }
}

// The rigid block path's kernels (see RigidBlockJob).

// The weighted earlier stages of a stage or the finish, Terms of them, copied out of the
// job: held in a local, no store of the loop can change them, and with Terms a constant the
// sums unroll.
template <int Terms, class T>
struct WeightedStages {
  static constexpr int kCount = Terms > 0 ? Terms : 1;
  T weight[kCount];
  const T* kx[kCount][3];
  const T* kv[kCount][3];
  const T* kq[kCount][4];
  const T* kl[kCount][3];

  explicit WeightedStages(const RigidBlockJob<T>& job) {
    for (int j = 0; j < Terms; ++j) {
      const int t = job.term[j];
      weight[j] = job.weight[j];
      for (int d = 0; d < 3; ++d) kx[j][d] = job.kx[t][d], kv[j][d] = job.kv[t][d], kl[j][d] = job.kl[t][d];
      for (int d = 0; d < 4; ++d) kq[j][d] = job.kq[t][d];
    }
  }

  // base + sum_j w_j k_j, the terms in the job's order.
  template <class V, int N>
  KINEMA_INLINE Vec<V, N> add_to(const Vec<V, N>& base, const T* const (&k)[kCount][N], std::size_t i) const {
    Vec<V, N> sum = base;
    for (int j = 0; j < Terms; ++j) {
      const Vec<V, N> kj = load_n<N, V>(k[j], i);
      for (int d = 0; d < N; ++d) sum.c[d] = mul_add(V(weight[j]), kj.c[d], sum.c[d]);
    }
    return sum;
  }
};

// Stage state y0 + sum_j w_j k_j, its angular velocity, and zeroed outputs. A stage whose x,
// q and L are the bodies' own (xs is x: stage 0) stores only v of them.
template <int Terms, class V>
void rigid_block_stage_of(const RigidBlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const WeightedStages<Terms, value_t<V>> w(job);
  const Vec<V> zero{{V(0), V(0), V(0)}};
  const bool in_place = job.xs[0] == job.x[0];
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> x = w.template add_to<V>(load3<V>(job.x, i), w.kx, i);
    const Vec<V> v = w.template add_to<V>(load3<V>(job.v, i), w.kv, i);
    const Quat4<V> q = w.template add_to<V>(load_n<4, V>(job.q, i), w.kq, i);
    const Vec<V> l = w.template add_to<V>(load3<V>(job.l, i), w.kl, i);
    store3(job.vs, i, v);
    if (!in_place) {
      store3(job.xs, i, x);
      store_n<4, V>(job.qs, i, q);
      store3(job.ls, i, l);
    }
    store3(job.omega, i, angular_velocity(rotation(q), load3<V>(job.inv_inertia, i), l));
    store3(job.force, i, zero);
    store3(job.torque, i, zero);
  }
}

template <class V>
void rigid_block_stage(const RigidBlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  assert(job.terms >= 0 && job.terms <= kMaxStages);
  static_for<kMaxStages + 1>([&](auto terms) {
    if (terms == job.terms) rigid_block_stage_of<terms, V>(job, begin, end);
  });
}

// The stage's rates from its state and what the callbacks added: kv = local accelerations +
// inv_mass F, kq = 1/2 (0, omega) q, kl = local torques + the callbacks' torque.
template <bool Quadratic, bool Central, class V>
void rigid_block_rates(const RigidBlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const Forces<V> f(job.forces);
  const Rotational<V> rf(job.rotation);
  const int s = job.stage;
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const V inv_mass = load<V>(job.inv_mass + i);
    auto body = body_terms_at<Applied::if_present, true>(f, inv_mass, job.per_body, i);
    add_applied(body, f, inv_mass, load3<V>(job.force, i));
    const Vec<V> x = load3<V>(job.xs, i), v = load3<V>(job.vs, i), omega = load3<V>(job.omega, i);
    const Quat4<V> q = load_n<4, V>(job.qs, i);
    store3(job.kv[s], i, accel_at<Quadratic, Central>(f, body, x, v));
    store_n<4, V>(job.kq[s], i, quaternion_rate(omega, q));
    Vec<V> extra = load3<V>(job.torque, i), applied_storage;
    if (const Vec<V>* applied = applied_torque_at<V>(job.applied_torque, i, applied_storage)) {
      for (int d = 0; d < 3; ++d) extra.c[d] = extra.c[d] + applied->c[d];
    }
    // The rotation only where point forces turn with the body.
    const Vec<V> tau = torque(rf, body, rf.point_count > 0 ? rotation(q) : Rotation<V>{}, omega, &extra);
    V damping_storage;
    store3(job.kl[s], i, damped(tau, body, neg_damping_at<V>(job.angular_damping, i, damping_storage), load3<V>(job.ls, i)));
  }
}

// y1 = y0 + sum_j w_j k_j over every stage; q renormalized.
template <int Terms, class V>
void rigid_block_finish_of(const RigidBlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const WeightedStages<Terms, value_t<V>> w(job);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    store3(job.x, i, w.template add_to<V>(load3<V>(job.x, i), w.kx, i));
    store3(job.v, i, w.template add_to<V>(load3<V>(job.v, i), w.kv, i));
    const Quat4<V> q = w.template add_to<V>(load_n<4, V>(job.q, i), w.kq, i);
    store_n<4, V>(job.q, i, job.renormalize ? normalized(q) : q);
    store3(job.l, i, w.template add_to<V>(load3<V>(job.l, i), w.kl, i));
  }
}

template <class V>
void rigid_block_finish(const RigidBlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  assert(job.terms >= 0 && job.terms <= kMaxStages);
  static_for<kMaxStages + 1>([&](auto terms) {
    if (terms == job.terms) rigid_block_finish_of<terms, V>(job, begin, end);
  });
}

// A drift's turn of q with the current L (Euler, or the midpoint rule), as the fused
// kick-drift kernels turn it; q is renormalized after each drift, not once per step.
template <class V>
void rigid_block_turn(const RigidBlockJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const V step(job.turn_step), half(value_t<V>(0.5) * job.turn_step);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> inv_inertia = load3<V>(job.inv_inertia, i), l = load3<V>(job.l, i);
    auto rate = [&](const Quat4<V>& q) { return quaternion_rate(angular_velocity(rotation(q), inv_inertia, l), q); };
    const Quat4<V> q = load_n<4, V>(job.q, i);
    const Quat4<V> turned = job.turn_order >= 2 ? step_by(step, rate(step_by(half, rate(q), q)), q)
                                                : step_by(step, rate(q), q);
    store_n<4, V>(job.q, i, job.renormalize ? normalized(turned) : turned);
  }
}

template <class V>
void interpolate(const InterpolateJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  const V alpha(job.alpha);
  for (std::size_t i = begin; i < end; i += Lane<V>::width) {
    const Vec<V> p = load3<V>(job.previous, i), c = load3<V>(job.current, i);
    Vec<V> out;
    for (int d = 0; d < 3; ++d) {
      const V diff = c.c[d] - p.c[d];
      // Ends far apart, near T's range, whose difference overflows: the weighted sum of both,
      // which cannot (and gives each end at alpha 0 and 1).
      out.c[d] = pick(diff - diff == V(0), mul_add(alpha, diff, p.c[d]), mul_add(alpha, c.c[d], (V(1) - alpha) * p.c[d]));
    }
    store3(job.out, i, out);
    if (job.out_q[0] == nullptr) continue;
    const Quat4<V> a = load_n<4, V>(job.previous_q, i);
    Quat4<V> b = load_n<4, V>(job.current_q, i);
    const V dot = mul_add(a.c[0], b.c[0], mul_add(a.c[1], b.c[1], mul_add(a.c[2], b.c[2], a.c[3] * b.c[3])));
    Quat4<V> q;
    for (int k = 0; k < 4; ++k) {
      b.c[k] = pick(dot < V(0), -b.c[k], b.c[k]);  // the short arc
      q.c[k] = mul_add(alpha, b.c[k] - a.c[k], a.c[k]);
    }
    store_n<4, V>(job.out_q, i, normalized(q));
  }
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
