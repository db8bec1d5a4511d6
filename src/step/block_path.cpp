#include "step/block_path.hpp"

#include <algorithm>

namespace kinema {

template <class T>
BlockPath<T>::BlockPath(const ForceModel<T>& forces, const Method& method, int builtin,
                        const kernels::KernelTable<T>& table, const kernels::LocalForces<T>& local)
    : forces_(forces), method_(method), table_(table), local_(local),
      stage_fn_(table.block_stage[builtin]),
      rates_fn_(table.block_rates[local.has_quadratic()][local.has_central()]),
      finish_fn_(table.block_finish[builtin]),
      kick_fn_(table.block_kick[local.has_quadratic()][local.has_central()]) {}

template <class T>
void BlockPath<T>::reserve(std::size_t padded) {
  if (padded <= capacity_) return;
  const bool rk = method_.kind == MethodKind::runge_kutta;
  const int stages = rk ? method_.tableau.stages : 0;
  for (int s = 0; s < stages; ++s) {
    for (int d = 0; d < 3; ++d) {
      if (s > 0) xs_[s][d].resize(padded), vs_[s][d].resize(padded);
      kv_[s][d].resize(padded);
    }
  }
  for (auto& a : force_) a.resize(padded);
  if (may_throw()) {
    for (auto& a : saved_) a.resize(padded);
  }
  capacity_ = padded;
}

template <class T>
std::size_t BlockPath<T>::bytes() const {
  std::size_t n = 0;
  auto add = [&](const auto& arrays) {
    for (const AlignedArray<T>& a : arrays) n += a.size() * sizeof(T);
  };
  for (int s = 0; s < kMaxStages; ++s) add(xs_[s]), add(vs_[s]), add(kv_[s]);
  add(force_), add(saved_);
  return n;
}

template <class T>
void BlockPath<T>::prepare(const StepContext<T>& c) {
  kernels::BlockJob<T> j{};
  j.bodies = arrays(c.bodies);
  for (int s = 0; s < kMaxStages; ++s) {
    for (int d = 0; d < 3; ++d) {
      j.xs[s][d] = s == 0 ? j.bodies.x[d] : xs_[s][d].data();
      j.vs[s][d] = s == 0 ? j.bodies.v[d] : vs_[s][d].data();
      j.kv[s][d] = kv_[s][d].data();
    }
  }
  for (int d = 0; d < 3; ++d) j.force[d] = force_[d].data();
  j.forces = local_;
  j.h = c.h;
  j.accel_scale = c.accel_scale;
  job_ = j;
  if (method_.kind == MethodKind::kick_drift) {
    for (int k = 0; k < method_.scheme.count; ++k) op_steps_[k] = T(method_.scheme.ops[k].weight) * c.h;
  }
}

template <class T>
void BlockPath<T>::step_block(Block b, double t0) {
  if (method_.kind == MethodKind::runge_kutta) return runge_kutta_step(b, t0);
  kick_drift_step(b, t0);
}

// The callbacks at stage s's state, time t.
template <class T>
void BlockPath<T>::call_back(int s, Block b, double t) const {
  const std::size_t i = b.begin;
  ParticleBlock<T> v;
  v.begin = i, v.count = b.end - b.begin, v.t = t;
  v.px = job_.xs[s][0] + i, v.py = job_.xs[s][1] + i, v.pz = job_.xs[s][2] + i;
  v.vx = job_.vs[s][0] + i, v.vy = job_.vs[s][1] + i, v.vz = job_.vs[s][2] + i;
  v.inv_mass = job_.bodies.inv_mass + i;
  v.fx = job_.force[0] + i, v.fy = job_.force[1] + i, v.fz = job_.force[2] + i;
  for (const auto& callback : forces_.callbacks()) callback(v);
}

template <class T>
void BlockPath<T>::runge_kutta_step(Block b, double t0) {
  const ButcherTableau& tab = method_.tableau;
  for (int s = 0; s < tab.stages; ++s) {
    stage_fn_(job_, s, b.begin, b.end);
    call_back(s, b, t0 + tab.c[s] * double(job_.h));
    rates_fn_(job_, s, b.begin, b.end);
  }
  finish_fn_(job_, b.begin, b.end);
}

template <class T>
void BlockPath<T>::kick_drift_step(Block b, double t0) {
  const KickDriftScheme& scheme = method_.scheme;
  for (int k = 0; k < scheme.count; ++k) {
    if (scheme.ops[k].kind == OpKind::drift) {
      table_.block_drift(job_, op_steps_[k], b.begin, b.end);
      continue;
    }
    // A kick's state is the bodies' own: no stage kernel runs to zero the forces.
    for (T* f : job_.force) std::fill(f + b.begin, f + b.end, T(0));
    call_back(0, b, t0 + scheme.ops[k].time * double(job_.h));
    kick_fn_(job_, op_steps_[k], b.begin, b.end);
  }
}

template <class T>
void BlockPath<T>::keep_block(Block b) {
  for (int d = 0; d < 3; ++d) {
    std::copy(job_.bodies.x[d] + b.begin, job_.bodies.x[d] + b.end, saved_[d].data() + b.begin);
    std::copy(job_.bodies.v[d] + b.begin, job_.bodies.v[d] + b.end, saved_[3 + d].data() + b.begin);
  }
}

template <class T>
void BlockPath<T>::restore_block(Block b) {
  for (int d = 0; d < 3; ++d) {
    std::copy(saved_[d].data() + b.begin, saved_[d].data() + b.end, job_.bodies.x[d] + b.begin);
    std::copy(saved_[3 + d].data() + b.begin, saved_[3 + d].data() + b.end, job_.bodies.v[d] + b.begin);
  }
}

template class BlockPath<float>;
template class BlockPath<double>;

}  // namespace kinema
