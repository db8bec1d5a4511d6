#include "step/rigid_block_path.hpp"

#include <algorithm>
#include <cmath>

#include "kernels/reductions.hpp"
#include "step/step_context.hpp"

namespace kinema {

template <class T>
RigidBlockPath<T>::RigidBlockPath(const ForceModel<T>& forces, const Method& method,
                                  const kernels::KernelTable<T>& table, const LoweredForces<T>& lowered)
    : forces_(forces), method_(method), table_(table), lowered_(lowered), coupling_(forces) {}

template <class T>
void RigidBlockPath<T>::reserve(std::size_t padded) {
  if (padded <= capacity_) return;
  const int stages = method_.kind == MethodKind::runge_kutta ? method_.tableau.stages : 1;
  auto grow = [&](auto& arrays) {
    for (AlignedArray<T>& a : arrays) a.resize(padded);
  };
  grow(xs_), grow(ls_), grow(omega_), grow(force_), grow(torque_), grow(qs_);
  for (int s = 0; s < stages; ++s) grow(vs_[s]), grow(kv_[s]), grow(kl_[s]), grow(kq_[s]);
  // step_all may keep the state with coupled terms, and an attempt always does.
  if (may_throw() || coupled() || method_.embedded_order > 0) grow(saved_);
  if (may_throw()) mass_.resize(padded);  // user code reads masses: callbacks, coupled terms
  if (method_.embedded_order > 0) block_error_.resize(block_count(padded));
  capacity_ = padded;
}

template <class T>
std::size_t RigidBlockPath<T>::bytes() const {
  std::size_t n = 0;
  auto add = [&](const auto& arrays) {
    for (const AlignedArray<T>& a : arrays) n += a.size() * sizeof(T);
  };
  add(xs_), add(ls_), add(omega_), add(force_), add(torque_), add(qs_), add(saved_);
  n += mass_.size() * sizeof(T);
  for (int s = 0; s < kMaxStages; ++s) add(vs_[s]), add(kv_[s]), add(kl_[s]), add(kq_[s]);
  return n;
}

// The state arrays of a set, in the order keep_block saves them.
template <class T>
std::array<T*, 13> state_of(RigidBodySet<T>& b) {
  return {b.position_data(0), b.position_data(1), b.position_data(2), b.velocity_data(0), b.velocity_data(1),
          b.velocity_data(2), b.q(0), b.q(1), b.q(2), b.q(3), b.l(0), b.l(1), b.l(2)};
}

template <class T>
void RigidBlockPath<T>::keep_block(const Call& call, Block b) {
  const std::array<T*, 13> state = state_of(call.bodies);
  for (std::size_t a = 0; a < state.size(); ++a) std::copy(state[a] + b.begin, state[a] + b.end, saved_[a].data() + b.begin);
}

template <class T>
void RigidBlockPath<T>::restore_block(const Call& call, Block b) {
  const std::array<T*, 13> state = state_of(call.bodies);
  for (std::size_t a = 0; a < state.size(); ++a) {
    std::copy(saved_[a].data() + b.begin, saved_[a].data() + b.end, state[a] + b.begin);
  }
}

template <class T>
kernels::RigidBlockJob<T> RigidBlockPath<T>::job(const Call& call) {
  RigidBodySet<T>& b = call.bodies;
  kernels::RigidBlockJob<T> j{};  // once per call (prepare)
  for (int d = 0; d < 3; ++d) {
    j.x[d] = b.position_data(d), j.v[d] = b.velocity_data(d), j.l[d] = b.l(d);
    j.inv_inertia[d] = b.inv_inertia(d);
    j.applied_torque[d] = b.applied_torque_data(d);
    j.xs[d] = xs_[d].data(), j.ls[d] = ls_[d].data();
    j.omega[d] = omega_[d].data();
    j.force[d] = force_[d].data(), j.torque[d] = torque_[d].data();
  }
  for (int k = 0; k < 4; ++k) j.q[k] = b.q(k), j.qs[k] = qs_[k].data();
  j.per_body = per_body(b.centers());
  j.angular_damping = b.parameters().data(BodyParameter::angular_damping);
  for (int s = 0; s < kMaxStages; ++s) {
    for (int d = 0; d < 3; ++d) {
      j.kx[s][d] = vs_[s][d].data();
      j.kv[s][d] = kv_[s][d].data(), j.kl[s][d] = kl_[s][d].data();
    }
    for (int k = 0; k < 4; ++k) j.kq[s][k] = kq_[s][k].data();
  }
  j.inv_mass = b.centers().inv_mass();
  j.forces = lowered_.rigid;
  j.rotation = lowered_.rotation;
  j.renormalize = call.renormalize;
  padded_ = b.padded_size();
  return j;
}

// `base` for stage s (its state into stage s's velocity arrays, its rates into slot s), with
// the nonzero weights among the first `count` of a tableau row, times h.
template <class T>
kernels::RigidBlockJob<T> RigidBlockPath<T>::with_terms(const kernels::RigidBlockJob<T>& base,
                                                        const std::array<double, kMaxStages>& row, int count, T h,
                                                        int s) {
  kernels::RigidBlockJob<T> j = base;
  for (int d = 0; d < 3; ++d) j.vs[d] = vs_[s][d].data();
  j.stage = s;
  j.terms = 0;
  for (int k = 0; k < count; ++k) {
    if (row[k] == 0) continue;
    j.term[j.terms] = k;
    j.weight[j.terms++] = T(row[k]) * h;
  }
  return j;
}

// Every phase's job for the call, so that a slice of a block only runs kernels.
template <class T>
void RigidBlockPath<T>::prepare(const Call& call) {
  coupling_.check_reach(call.bodies.size());
  const kernels::RigidBlockJob<T> base = job(call);
  if (may_throw()) fill_masses(base.inv_mass, mass_.data(), call.bodies.padded_size());
  if (method_.kind == MethodKind::runge_kutta) {
    const ButcherTableau& tab = method_.tableau;
    for (int s = 0; s < tab.stages; ++s) stage_jobs_[s] = with_terms(base, tab.a[s], s, call.h, s);
    // Stage 0 is the bodies' own state: it reads x, q and L where they are (v is copied: it is
    // the position rate the finish and the error estimate read once v has moved on).
    for (int d = 0; d < 3; ++d) stage_jobs_[0].xs[d] = base.x[d], stage_jobs_[0].ls[d] = base.l[d];
    for (int k = 0; k < 4; ++k) stage_jobs_[0].qs[k] = base.q[k];
    finish_job_ = with_terms(base, tab.b, tab.stages, call.h, 0);
    return;
  }
  stage_jobs_[0] = with_terms(base, {}, 0, call.h, 0);  // a kick's rates at the bodies' state
  for (int k = 0; k < method_.scheme.count; ++k) {
    op_steps_[k] = T(method_.scheme.ops[k].weight) * call.h;
    turn_jobs_[k] = base;
    turn_jobs_[k].turn_step = op_steps_[k];
    turn_jobs_[k].turn_order = method_.order >= 2 ? 2 : 1;
  }
}

template <class T>
void RigidBlockPath<T>::step_block(const Call& call, Block b, double t0) {
  if (method_.kind == MethodKind::runge_kutta) return runge_kutta_step(b, t0, call.h);
  kick_drift_step(b, t0, call.h);
}

template <class T>
RigidBlock<T> RigidBlockPath<T>::view(const kernels::RigidBlockJob<T>& j, Block b, double t) const {
  const std::size_t i = b.begin;
  RigidBlock<T> v;
  v.begin = i, v.count = b.end - b.begin, v.t = t;
  v.px = j.xs[0] + i, v.py = j.xs[1] + i, v.pz = j.xs[2] + i;
  v.vx = j.vs[0] + i, v.vy = j.vs[1] + i, v.vz = j.vs[2] + i;
  v.qw = j.qs[0] + i, v.qx = j.qs[1] + i, v.qy = j.qs[2] + i, v.qz = j.qs[3] + i;
  v.wx = j.omega[0] + i, v.wy = j.omega[1] + i, v.wz = j.omega[2] + i;
  v.lx = j.ls[0] + i, v.ly = j.ls[1] + i, v.lz = j.ls[2] + i;
  v.inv_mass = j.inv_mass + i;
  v.mass = mass_.data() + i;
  v.inv_ix = j.inv_inertia[0] + i, v.inv_iy = j.inv_inertia[1] + i, v.inv_iz = j.inv_inertia[2] + i;
  v.fx = j.force[0] + i, v.fy = j.force[1] + i, v.fz = j.force[2] + i;
  v.tx = j.torque[0] + i, v.ty = j.torque[1] + i, v.tz = j.torque[2] + i;
  return v;
}

template <class T>
void RigidBlockPath<T>::evaluate(const kernels::RigidBlockJob<T>& j, Block b, double t) {
  table_.rigid_block_stage(j, b.begin, b.end);
  rates(j, b, t);
}

template <class T>
RigidStage<T> RigidBlockPath<T>::stage_of(const kernels::RigidBlockJob<T>& j) {
  return {{j.xs[0], j.xs[1], j.xs[2]},     {j.vs[0], j.vs[1], j.vs[2]},
          {j.qs[0], j.qs[1], j.qs[2], j.qs[3]}, {j.omega[0], j.omega[1], j.omega[2]},
          {j.force[0], j.force[1], j.force[2]}, {j.torque[0], j.torque[1], j.torque[2]}};
}

// Each body spring once at the stage, every body's stage state written: a pass of its own.
template <class T>
void RigidBlockPath<T>::springs_pass(const kernels::RigidBlockJob<T>& j, const Workers& w) {
  if (!coupling_.coupled()) return;
  const RigidStage<T> stage = stage_of(j);
  for_each_block(w, coupling_.spring_count(), [&](Block b) { coupling_.evaluate_springs(stage, b.begin, b.end); });
}

template <class T>
void RigidBlockPath<T>::rates(const kernels::RigidBlockJob<T>& j, Block b, double t) {
  if (!coupling_.empty()) coupling_.add(stage_of(j), b.begin, b.end);
  if (forces_.coupled()) add_coupled(j, b, t);
  if (!forces_.rigid_callbacks().empty()) {  // their masses exist (reserve) only then
    const RigidBlock<T> v = view(j, b, t);
    for (const auto& callback : forces_.rigid_callbacks()) callback(v);
  }
  table_.rigid_block_rates[lowered_.rigid.has_quadratic()][lowered_.rigid.has_central()](j, b.begin, b.end);
  if (const auto& nbody = lowered_.coupled.nbody) {
    kernels::NBodyJob<T> g{};
    for (int d = 0; d < 3; ++d) g.x[d] = j.xs[d], g.acc[d] = j.kv[j.stage][d];
    g.inv_mass = j.inv_mass;
    g.sources = padded_;
    g.eps2 = lowered_.coupled.eps2;
    g.scale_G = T(nbody->G);
    g.fast = nbody->fast;
    table_.nbody(g, b.begin, b.end);
  }
}

// The coupled terms the centres feel as particles do: spring pairs and CoupledTerms, as forces.
template <class T>
void RigidBlockPath<T>::add_coupled(const kernels::RigidBlockJob<T>& j, Block b, double t) {
  if (!lowered_.coupled.springs.empty()) table_.springs(lowered_.coupled.springs.job(j.xs, j.vs, j.force), b.begin, b.end);
  if (forces_.coupled_terms().empty()) return;
  const ParticleState<T> all{padded_, j.xs[0], j.xs[1], j.xs[2], j.vs[0], j.vs[1], j.vs[2], j.inv_mass};
  ParticleBlock<T> view;
  view.begin = b.begin, view.count = b.end - b.begin, view.t = t;
  view.px = j.xs[0] + b.begin, view.py = j.xs[1] + b.begin, view.pz = j.xs[2] + b.begin;
  view.vx = j.vs[0] + b.begin, view.vy = j.vs[1] + b.begin, view.vz = j.vs[2] + b.begin;
  view.inv_mass = j.inv_mass + b.begin;
  view.mass = mass_.data() + b.begin;
  view.fx = j.force[0] + b.begin, view.fy = j.force[1] + b.begin, view.fz = j.force[2] + b.begin;
  for (const auto& term : forces_.coupled_terms()) term->accumulate(all, view);
}

// Stage s from y0 + h sum_j a_sj k_j, then y1 = y0 + h sum_j b_j k_j.
template <class T>
void RigidBlockPath<T>::runge_kutta_step(Block b, double t0, T h) {
  const ButcherTableau& tab = method_.tableau;
  for (int s = 0; s < tab.stages; ++s) evaluate(stage_jobs_[s], b, t0 + tab.c[s] * double(h));
  table_.rigid_block_finish(finish_job_, b.begin, b.end);
}

// Kicks change v and L by w h times the rates at the bodies' state; drifts move x with v and
// turn q with L (Euler for first-order schemes, the midpoint rule for second-order ones), as
// the fused kick-drift kernels do.
template <class T>
void RigidBlockPath<T>::kick_drift_step(Block b, double t0, T h) {
  const KickDriftScheme& scheme = method_.scheme;
  const kernels::RigidBlockJob<T>& j = stage_jobs_[0];
  for (int k = 0; k < scheme.count; ++k) {
    if (scheme.ops[k].kind == OpKind::kick) {
      evaluate(j, b, t0 + scheme.ops[k].time * double(h));
      combine(j.v, j.kv[0], op_steps_[k], b);
      combine(j.l, j.kl[0], op_steps_[k], b);
    } else {
      combine(j.x, j.v, op_steps_[k], b);
      table_.rigid_block_turn(turn_jobs_[k], b.begin, b.end);
    }
  }
}

template <class T>
double RigidBlockPath<T>::attempt(const Call& call, const Workers& w, double t0, double rtol, double atol) {
  const std::size_t n = call.bodies.padded_size();
  for_each_block(w, n, [&](Block b) { keep_block(call, b); });
  try {  // the error's pass too: a host's enqueue that throws there leaves the step half taken
    if (coupled()) {
      run_phases(call, w, t0, nullptr);
    } else {
      for_each_block(w, n, [&](Block b) { runge_kutta_step(b, t0, call.h); });
    }
    for_each_block(w, n, [&](Block b) { block_error_[b.begin / kBlockBodies] = block_error(call, b, rtol, atol); });
  } catch (...) {
    for (std::size_t i = 0; i < block_count(n); ++i) restore_block(call, block(i, n));
    throw;
  }
  double sum = 0;
  for (std::size_t i = 0; i < block_count(n); ++i) sum += block_error_[i];
  return std::sqrt(sum / (13.0 * double(std::max<std::size_t>(call.bodies.size(), 1))));
}

template <class T>
void RigidBlockPath<T>::take_back(const Call& call, const Workers& w) {
  const std::size_t n = call.bodies.padded_size();
  try {
    for_each_block(w, n, [&](Block b) { restore_block(call, b); });
  } catch (...) {  // a host's enqueue that throws: put every block back here
    for (std::size_t i = 0; i < block_count(n); ++i) restore_block(call, block(i, n));
    throw;
  }
}

template <class T>
void RigidBlockPath<T>::evaluate_rates(const Call& call, const Workers& w, double t) {
  prepare(call);
  const std::size_t n = call.bodies.padded_size();
  const kernels::RigidBlockJob<T>& j = stage_jobs_[0];  // stage 0 reads the bodies, writes scratch
  for_each_block(w, n, [&](Block b) { table_.rigid_block_stage(j, b.begin, b.end); });
  springs_pass(j, w);
  for_each_block(w, n, [&](Block b) { rates(j, b, t); });
}

template <class T>
const T* RigidBlockPath<T>::rate(int component, int s) const {
  if (component < 3) return vs_[s][component].data();  // stage velocities: the position rates
  if (component < 6) return kv_[s][component - 3].data();
  if (component < 10) return kq_[s][component - 6].data();
  return kl_[s][component - 10].data();
}

// The block's sum of (e / (atol + rtol max(|y0|, |y1|)))^2, e = h sum_s (b_s - b_hat_s) k_s.
template <class T>
double RigidBlockPath<T>::block_error(const Call& call, Block b, double rtol, double atol) const {
  const ButcherTableau& tab = method_.tableau;
  std::array<double, kMaxStages> w{};
  for (int s = 0; s < tab.stages; ++s) w[s] = (tab.b[s] - tab.b_hat[s]) * double(call.h);
  const std::array<T*, 13> state = state_of(call.bodies);
  // Real bodies only: padding stays at rest.
  const std::size_t size = call.bodies.size(), count = std::min(b.end, size) - std::min(b.begin, size);
  double sum = 0;
  for (int a = 0; a < 13; ++a) {
    std::array<const T*, kMaxStages> k{};
    for (int s = 0; s < tab.stages; ++s) k[s] = rate(a, s) + b.begin;
    sum += error_squares(saved_[a].data() + b.begin, state[a] + b.begin, k.data(), w.data(), tab.stages, rtol, atol, count);
  }
  return sum;
}

template <class T>
bool RigidBlockPath<T>::keeps_state(const Workers& w, const StopRequest* stop) const {
  const bool polls = stop != nullptr && *stop && (lowered_.coupled.nbody || may_throw());
  return may_throw() || !enqueue_never_throws(w.jobs) || (method_.kind == MethodKind::kick_drift && polls);
}

template <class T>
void RigidBlockPath<T>::step_all(const Call& call, const Workers& w, double t0, const StopRequest* stop) {
  if (!keeps_state(w, stop)) return run_phases(call, w, t0, stop);
  const std::size_t n = call.bodies.padded_size();
  for_each_block(w, n, [&](Block b) { keep_block(call, b); });
  try {
    run_phases(call, w, t0, stop);
  } catch (...) {
    for (std::size_t i = 0; i < block_count(n); ++i) restore_block(call, block(i, n));
    throw;
  }
}

// The phases of step_block, each a pass over every block: a stage's state everywhere before
// any body's rates read it.
template <class T>
void RigidBlockPath<T>::run_phases(const Call& call, const Workers& w, double t0, const StopRequest* stop) {
  const std::size_t n = call.bodies.padded_size();
  const bool polls = stop != nullptr && *stop && (lowered_.coupled.nbody || may_throw());
  // Gravity costs a block n interactions per body: worth the threads at any n.
  const Workers rates_on = lowered_.coupled.nbody ? all_workers(*w.jobs) : w;
  const auto state_pass = [&](const kernels::RigidBlockJob<T>& j) {
    for_each_block(w, n, [&](Block b) { table_.rigid_block_stage(j, b.begin, b.end); });
    springs_pass(j, w);
  };
  const auto rates_pass = [&](const kernels::RigidBlockJob<T>& j, double t, auto&& then) {
    for_each_block(rates_on, n, [&](Block b) {
      if (polls && (*stop)()) throw Stopped();
      rates(j, b, t);
      then(b);
    });
  };
  if (method_.kind == MethodKind::runge_kutta) {
    const ButcherTableau& tab = method_.tableau;
    for (int s = 0; s < tab.stages; ++s) {
      state_pass(stage_jobs_[s]);
      rates_pass(stage_jobs_[s], t0 + tab.c[s] * double(call.h), [](Block) {});
    }
    for_each_block(w, n, [&](Block b) { table_.rigid_block_finish(finish_job_, b.begin, b.end); });
    return;
  }
  const KickDriftScheme& scheme = method_.scheme;
  const kernels::RigidBlockJob<T>& j = stage_jobs_[0];
  for (int k = 0; k < scheme.count; ++k) {
    if (scheme.ops[k].kind == OpKind::drift) {
      for_each_block(w, n, [&](Block b) {
        combine(j.x, j.v, op_steps_[k], b);
        table_.rigid_block_turn(turn_jobs_[k], b.begin, b.end);
      });
      continue;
    }
    state_pass(j);
    // A kick changes v and L, which no block's rates read (they read the stage's copies).
    rates_pass(j, t0 + scheme.ops[k].time * double(call.h), [&](Block b) {
      combine(j.v, j.kv[0], op_steps_[k], b);
      combine(j.l, j.kl[0], op_steps_[k], b);
    });
  }
}

template <class T>
void RigidBlockPath<T>::combine(T* const out[3], const T* const rate[3], T step, Block b) const {
  kernels::CombineJob<T> c{};
  for (int d = 0; d < 3; ++d) c.c.in[d] = c.c.out[d] = out[d];
  c.c.set(kernels::row_sum({1}), 1, [&](int) { return std::array<const T*, 3>{rate[0], rate[1], rate[2]}; });
  c.c.step = step;
  table_.combine(c, b.begin, b.end);
}

template class RigidBlockPath<float>;
template class RigidBlockPath<double>;

}  // namespace kinema
