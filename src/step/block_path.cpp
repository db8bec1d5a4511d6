#include "step/block_path.hpp"

#include <algorithm>

namespace kinema {

template <class T>
BlockPath<T>::BlockPath(const ForceModel<T>& forces, const Method& method, int builtin,
                        const kernels::KernelTable<T>& table, const kernels::LocalForces<T>& local)
    : forces_(forces), method_(method), table_(table), local_(local),
      advance_fn_(table.block_advance[builtin][local.has_quadratic()][local.has_central()]),
      kick_fn_(table.block_kick[local.has_quadratic()][local.has_central()]) {}

template <class T>
kernels::SliceLayout BlockPath<T>::layout() const {
  return {method_.kind == MethodKind::runge_kutta ? method_.tableau.stages : 1};
}

template <class T>
void BlockPath<T>::reserve(std::size_t padded) {
  if (padded <= capacity_) return;
  region_ = (layout().arrays() + 1) * kernels::kSliceBodies<T>;
  scratch_.resize(block_count(padded) * region_);
  if (may_throw()) {
    for (auto& a : saved_) a.resize(padded);
  }
  capacity_ = padded;
}

template <class T>
std::size_t BlockPath<T>::bytes() const {
  std::size_t n = scratch_.size() * sizeof(T);
  for (const AlignedArray<T>& a : saved_) n += a.size() * sizeof(T);
  return n;
}

template <class T>
void BlockPath<T>::prepare(const StepContext<T>& c) {
  kernels::BlockJob<T> j{};
  j.bodies = arrays(c.bodies);
  j.forces = local_;
  j.h = c.h;
  j.accel_scale = c.accel_scale;
  job_ = j;
  if (method_.kind == MethodKind::kick_drift) {
    for (int k = 0; k < method_.scheme.count; ++k) op_steps_[k] = T(method_.scheme.ops[k].weight) * c.h;
  }
}

template <class T>
T* BlockPath<T>::region(Block b) {
  return scratch_.data() + b.begin / kBlockBodies * region_;
}

template <class T>
void BlockPath<T>::begin_slice(Block slice) {
  fill_masses(job_.bodies.inv_mass + slice.begin, at(region(slice), layout().arrays()), slice.end - slice.begin);
}

template <class T>
void BlockPath<T>::step_block(Block slice, double t0) {
  T* scratch = region(slice);
  if (method_.kind == MethodKind::runge_kutta) return runge_kutta_step(slice, scratch, t0);
  kick_drift_step(slice, scratch, t0);
}

template <class T>
T* BlockPath<T>::at(T* scratch, std::size_t array) {
  return scratch + array * kernels::kSliceBodies<T>;
}

// The callbacks at stage s's state, time t.
template <class T>
void BlockPath<T>::call_back(int s, Block slice, T* scratch, double t) const {
  const std::size_t i = slice.begin;
  ParticleBlock<T> v;
  v.begin = i, v.count = slice.end - i, v.t = t;
  const kernels::SliceLayout l = layout();
  if (s == 0) {
    v.px = job_.bodies.x[0] + i, v.py = job_.bodies.x[1] + i, v.pz = job_.bodies.x[2] + i;
    v.vx = job_.bodies.v[0] + i, v.vy = job_.bodies.v[1] + i, v.vz = job_.bodies.v[2] + i;
  } else {
    v.px = at(scratch, l.xs(s, 0)), v.py = at(scratch, l.xs(s, 1)), v.pz = at(scratch, l.xs(s, 2));
    v.vx = at(scratch, l.vs(s, 0)), v.vy = at(scratch, l.vs(s, 1)), v.vz = at(scratch, l.vs(s, 2));
  }
  v.inv_mass = job_.bodies.inv_mass + i;
  v.mass = at(scratch, l.arrays());
  v.fx = at(scratch, l.force(0)), v.fy = at(scratch, l.force(1)), v.fz = at(scratch, l.force(2));
  for (const auto& callback : forces_.callbacks()) callback(v);
}

template <class T>
void BlockPath<T>::runge_kutta_step(Block slice, T* scratch, double t0) {
  const ButcherTableau& tab = method_.tableau;
  for (int s = 0; s < tab.stages; ++s) {
    call_back(s, slice, scratch, t0 + tab.c[s] * double(job_.h));
    advance_fn_(job_, scratch, s, slice.begin, slice.end - slice.begin);
  }
}

template <class T>
void BlockPath<T>::kick_drift_step(Block slice, T* scratch, double t0) {
  const KickDriftScheme& scheme = method_.scheme;
  for (int k = 0; k < scheme.count; ++k) {
    if (scheme.ops[k].kind == OpKind::drift) {
      table_.block_drift(job_, scratch, op_steps_[k], slice.begin, slice.end - slice.begin);
      continue;
    }
    call_back(0, slice, scratch, t0 + scheme.ops[k].time * double(job_.h));
    kick_fn_(job_, scratch, op_steps_[k], slice.begin, slice.end - slice.begin);
  }
}

template <class T>
void BlockPath<T>::keep_block(Block b) {
  for (int d = 0; d < 3; ++d) {
    std::copy(job_.bodies.x[d] + b.begin, job_.bodies.x[d] + b.end, saved_[d].data() + b.begin);
    std::copy(job_.bodies.v[d] + b.begin, job_.bodies.v[d] + b.end, saved_[3 + d].data() + b.begin);
  }
}

// A callback that threw left forces in its slice's scratch, where the kernels that read them
// leave zeros for the next callbacks.
template <class T>
void BlockPath<T>::restore_block(Block b) {
  std::fill_n(region(b), region_, T(0));
  for (int d = 0; d < 3; ++d) {
    std::copy(saved_[d].data() + b.begin, saved_[d].data() + b.end, job_.bodies.x[d] + b.begin);
    std::copy(saved_[3 + d].data() + b.begin, saved_[3 + d].data() + b.end, job_.bodies.v[d] + b.begin);
  }
}

template class BlockPath<float>;
template class BlockPath<double>;

}  // namespace kinema
