#include "step/staged_path.hpp"

#include "kernels/reductions.hpp"
#include "kinema/error.hpp"

#include <algorithm>
#include <cmath>

namespace kinema {

static_assert(kBlockBodies <= kernels::kMaxNBodyTargets && kBlockBodies % kernels::kSpringSlice == 0,
              "the coupled kernels take one block per call");

template <class T>
StagedPath<T>::StagedPath(const ForceModel<T>& forces, const Method& method,
                          const kernels::KernelTable<T>& table, const kernels::LocalForces<T>& local,
                          const CoupledForces<T>& coupled)
    : forces_(forces), method_(method), table_(table), local_(local), coupled_(coupled) {
  plan();
}

template <class T>
void StagedPath<T>::plan() {
  auto push = [&](PhaseKind k, int i) { phases_[phase_count_++] = {k, i}; };
  if (method_.kind == MethodKind::runge_kutta) {
    for (int s = 0; s < method_.tableau.stages; ++s) {
      push(PhaseKind::stage, s);
      if (coupled()) push(PhaseKind::coupled, s);
    }
    push(PhaseKind::finish, 0);
    return;
  }
  for (int k = 0; k < method_.scheme.count; ++k) {
    if (method_.scheme.ops[k].kind == OpKind::drift) {
      push(PhaseKind::drift, k);
      continue;
    }
    push(PhaseKind::stage, k);
    if (coupled()) push(PhaseKind::coupled, k);
    push(PhaseKind::kick, k);
  }
}

template <class T>
std::size_t StagedPath<T>::bytes() const {
  std::size_t n = 0;
  const auto add = [&](const auto& arrays) {
    for (const AlignedArray<T>& a : arrays) n += a.size() * sizeof(T);
  };
  for (int s = 0; s < kMaxStages; ++s) add(stage_x_[s]), add(stage_v_[s]), add(stage_a_[s]);
  add(force_);
  n += mass_.size() * sizeof(T);
  for (const auto& kept : saved_) add(kept);
  return n;
}

template <class T>
void StagedPath<T>::reserve(std::size_t padded) {
  if (padded <= capacity_) return;
  const int stages = method_.kind == MethodKind::runge_kutta ? method_.tableau.stages : 1;
  for (int s = 0; s < stages; ++s) {
    for (int d = 0; d < 3; ++d) {
      if (s > 0) stage_x_[s][d].resize(padded), stage_v_[s][d].resize(padded);
      stage_a_[s][d].resize(padded);
    }
  }
  if (needs_force_scratch()) {
    for (auto& f : force_) f.resize(padded);
  }
  if (user_views()) mass_.resize(padded);
  if (keeps_state()) {
    for (auto& kept : saved_) {
      for (auto& a : kept) a.resize(padded);
    }
  }
  if (method_.embedded_order > 0) {
    block_error_.resize(block_count(padded));
    block_saved_.resize(block_count(padded));
  }
  capacity_ = padded;
}

template <class T>
void StagedPath<T>::step(const StepContext<T>& c) {
  const bool may_tear = phases_change_bodies() && (polls(c) || !enqueue_never_throws(c.workers.jobs));
  if (!may_throw() && !may_tear) return run_phases(c);
  // User code runs in this step, or a stop request or a host's enqueue may end it between
  // two passes that each change the bodies: keep their state, so a throw leaves them as
  // they were.
  for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) { copy_state(c, b, true); });
  try {
    run_phases(c);
  } catch (...) {
    for (std::size_t i = 0; i < block_count(c.bodies.padded_size()); ++i) {
      copy_state(c, block(i, c.bodies.padded_size()), false);
    }
    throw;
  }
}

template <class T>
double StagedPath<T>::attempt(const StepContext<T>& c, const Attempt& a) {
  attempt_ = &a;
  std::fill(block_error_.begin(), block_error_.end(), 0.0);
  std::fill(block_saved_.begin(), block_saved_.end(), std::uint8_t(0));
  try {
    if (!saves_in_block()) {
      for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) { save_for_attempt(c, b); });
    }
    run_phases(c);
  } catch (...) {
    attempt_ = nullptr;
    take_back(c);
    throw;
  }
  attempt_ = nullptr;
  double sum = 0;
  for (std::size_t i = 0; i < block_count(c.bodies.padded_size()); ++i) sum += block_error_[i];
  return std::sqrt(sum / (6.0 * double(std::max<std::size_t>(c.bodies.size(), 1))));
}

template <class T>
void StagedPath<T>::take_back(const StepContext<T>& c) {
  const std::size_t n = c.bodies.padded_size();
  const auto restore = [&](Block b) {
    if (block_saved_[b.begin / kBlockBodies] != 0) copy_state(c, b, false);
  };
  try {
    for_each_block(c.workers, n, restore);
  } catch (...) {  // the host's enqueue threw, having run no block (kinema/job_system.hpp)
    for (std::size_t i = 0; i < block_count(n); ++i) restore(block(i, n));
    throw;
  }
}

template <class T>
void StagedPath<T>::save_for_attempt(const StepContext<T>& c, Block b) {
  copy_state(c, b, true);
  block_saved_[b.begin / kBlockBodies] = 1;
}

template <class T>
void StagedPath<T>::keep_last_stage() {
  std::swap(stage_a_[0], stage_a_[method_.tableau.stages - 1]);
}

template <class T>
void StagedPath<T>::evaluate_first_stage(const StepContext<T>& c) {
  first_stage_only_ = true;
  try {
    run_phases(c);
  } catch (...) {
    first_stage_only_ = false;
    throw;
  }
  first_stage_only_ = false;
}

template <class T>
void StagedPath<T>::copy_state(const StepContext<T>& c, Block b, bool save) {
  const auto body = arrays(c.bodies);
  for (int d = 0; d < 3; ++d) {
    T* const live[2] = {body.x[d], body.v[d]};
    for (int a = 0; a < 2; ++a) {
      T* kept = saved_[a][d].data();
      T* from = save ? live[a] : kept;
      T* to = save ? kept : live[a];
      std::copy(from + b.begin, from + b.end, to + b.begin);
    }
  }
}

template <class T>
void StagedPath<T>::run_phases(const StepContext<T>& c) {
  prepare(c);
  const std::size_t n = c.bodies.padded_size();
  if (coupled()) {
    for (int p = 0; p < phase_count_; ++p) {
      if (skipped(phases_[p])) continue;
      // Gravity costs a block n interactions per body: worth the threads at any n.
      const bool quadratic = phases_[p].kind == PhaseKind::coupled && coupled_.nbody;
      const Workers workers = quadratic ? all_workers(*c.workers.jobs) : c.workers;
      const bool poll = polls(c) && phases_[p].kind == PhaseKind::coupled;
      for_each_block(workers, n, [&](Block b) {
        if (poll && (*c.stop)()) throw Stopped();
        run(c, phases_[p], b);
      });
    }
    return;
  }
  for_each_block(c.workers, n, [&](Block b) { run_block(c, b); });
}

// Every phase of one block while it is in cache (no coupled terms).
template <class T>
void StagedPath<T>::run_block(const StepContext<T>& c, Block b) {
  if (attempt_ != nullptr && saves_in_block()) save_for_attempt(c, b);
  for (int p = 0; p < phase_count_; ++p) {
    if (!skipped(phases_[p])) run(c, phases_[p], b);
  }
}

// An attempt that reuses stage 0 evaluates nothing there; evaluate_first_stage runs stage 0
// alone.
template <class T>
bool StagedPath<T>::skipped(const Phase& p) const {
  const bool first = (p.kind == PhaseKind::stage || p.kind == PhaseKind::coupled) && p.index == 0;
  if (first_stage_only_) return !first;
  return first && p.kind == PhaseKind::coupled && attempt_ != nullptr && attempt_->reuse_scale > 0;
}

template <class T>
void StagedPath<T>::scale_first_stage(Block b) {
  const T scale = attempt_->reuse_scale;
  for (auto& a : stage_a_[0]) {
    for (std::size_t i = b.begin; i < b.end; ++i) a[i] *= scale;
  }
}

// Stage s's state is the bodies' own for stage 0, for a stage whose tableau row is all
// zero (nothing to add), and for every kick-drift stage; else its stage buffers.
template <class T>
bool StagedPath<T>::own_state(int s) const {
  if (s == 0 || method_.kind == MethodKind::kick_drift) return true;
  for (int j = 0; j < s; ++j) {
    if (method_.tableau.a[s][j] != 0) return false;
  }
  return true;
}

template <class T>
const T* StagedPath<T>::state_x(const StepContext<T>& c, int s, int d) const {
  return own_state(s) ? arrays(c.bodies).x[d] : stage_x_[s][d].data();
}

template <class T>
const T* StagedPath<T>::state_v(const StepContext<T>& c, int s, int d) const {
  return own_state(s) ? arrays(c.bodies).v[d] : stage_v_[s][d].data();
}

// Stage s's velocities (the x derivative) and accelerations, as three component arrays.
template <class T>
std::array<const T*, 3> StagedPath<T>::velocities(const StepContext<T>& c, int s) const {
  return {state_v(c, s, 0), state_v(c, s, 1), state_v(c, s, 2)};
}

template <class T>
std::array<const T*, 3> StagedPath<T>::accelerations(int s) const {
  return {stage_a_[s][0].data(), stage_a_[s][1].data(), stage_a_[s][2].data()};
}

template <class T>
int StagedPath<T>::accel_slot(const Phase& p) const {
  return method_.kind == MethodKind::runge_kutta ? p.index : 0;
}

template <class T>
double StagedPath<T>::phase_time(const StepContext<T>& c, const Phase& p) const {
  const double at = method_.kind == MethodKind::runge_kutta ? method_.tableau.c[p.index]
                                                             : method_.scheme.ops[p.index].time;
  return c.t0 + at * double(c.h);
}

template <class T>
void StagedPath<T>::run(const StepContext<T>& c, const Phase& p, Block b) {
  switch (p.kind) {
    case PhaseKind::stage: return run_stage(c, p, b);
    case PhaseKind::coupled: return run_coupled(c, p, b);
    case PhaseKind::finish: return run_finish(c, b);
    case PhaseKind::kick:
    case PhaseKind::drift: return run_kick_drift(p, b);
  }
}

// The jobs of every phase for a call's bodies and step size, built once per call rather than
// once per block: the block path runs a step's phases over slices of a few hundred bodies.
template <class T>
void StagedPath<T>::prepare(const StepContext<T>& c) {
  const int slots = method_.kind == MethodKind::runge_kutta ? method_.tableau.stages : 1;
  for (int s = 0; s < slots; ++s) stage_jobs_[s] = stage_job(c, s);
  if (method_.kind == MethodKind::runge_kutta) {
    finish_jobs_ = finish_jobs(c);
    return;
  }
  for (int k = 0; k < method_.scheme.count; ++k) kick_drift_jobs_[k] = kick_drift_job(c, k);
}

template <class T>
void StagedPath<T>::run_stage(const StepContext<T>& c, const Phase& p, Block b) {
  const int s = accel_slot(p);
  if (s == 0 && user_views()) {  // the views' masses, at a step's first stage (or each kick)
    fill_masses(c.bodies.inv_mass() + b.begin, mass_.data() + b.begin, b.end - b.begin);
  }
  if (s == 0 && attempt_ != nullptr && attempt_->reuse_scale > 0) return scale_first_stage(b);
  table_.stage[local_.has_quadratic()][local_.has_central()](stage_jobs_[s], b.begin, b.end);
  if (!needs_force_scratch()) return;
  for (auto& f : force_) std::fill(f.data() + b.begin, f.data() + b.end, T(0));
  const ParticleBlock<T> view = block_view(c, s, b, phase_time(c, p));
  for (const auto& callback : forces_.callbacks()) callback(view);
  if (!coupled()) add_forces(c, s, b);
}

template <class T>
kernels::StageJob<T> StagedPath<T>::stage_job(const StepContext<T>& c, int s) {
  kernels::StageJob<T> job{};
  job.accel_scale = c.accel_scale;
  job.inv_mass = c.bodies.inv_mass();
  job.forces = local_;
  auto body = arrays(c.bodies);
  job.per_body = body.per_body;
  for (int d = 0; d < 3; ++d) {
    job.x.in[d] = body.x[d];
    job.v.in[d] = body.v[d];
    job.x.out[d] = s > 0 ? stage_x_[s][d].data() : nullptr;
    job.v.out[d] = s > 0 ? stage_v_[s][d].data() : nullptr;
    job.acc[d] = stage_a_[s][d].data();
  }
  if (method_.kind == MethodKind::runge_kutta) {
    const kernels::RowSum row = kernels::row_sum(method_.tableau.a[s]);
    job.x.set(row, s, [&](int j) { return velocities(c, j); });
    job.v.set(row, s, [&](int j) { return accelerations(j); });
    set_steps(c, row, job.x, job.v);
  }
  return job;
}

template <class T>
void StagedPath<T>::set_steps(const StepContext<T>& c, const kernels::RowSum& row,
                              kernels::Combination<T>& x, kernels::Combination<T>& v) const {
  x.step = row.position_step(c.h);
  v.step = row.velocity_step<T>(kernels::acceleration_scale(method_.tableau));
}

template <class T>
ParticleBlock<T> StagedPath<T>::block_view(const StepContext<T>& c, int s, Block b, double t) {
  ParticleBlock<T> v;
  v.begin = b.begin;
  v.count = b.end - b.begin;
  v.t = t;
  v.px = state_x(c, s, 0) + b.begin, v.py = state_x(c, s, 1) + b.begin, v.pz = state_x(c, s, 2) + b.begin;
  v.vx = state_v(c, s, 0) + b.begin, v.vy = state_v(c, s, 1) + b.begin, v.vz = state_v(c, s, 2) + b.begin;
  v.inv_mass = c.bodies.inv_mass() + b.begin;
  v.mass = mass_.data() + b.begin;
  v.fx = force_[0].data() + b.begin, v.fy = force_[1].data() + b.begin, v.fz = force_[2].data() + b.begin;
  return v;
}

template <class T>
void StagedPath<T>::add_forces(const StepContext<T>& c, int s, Block b) {
  kernels::ForceJob<T> job{};
  for (int d = 0; d < 3; ++d) job.acc[d] = stage_a_[s][d].data(), job.force[d] = force_[d].data();
  job.inv_mass = c.bodies.inv_mass();
  job.scale = c.accel_scale;
  table_.add_forces(job, b.begin, b.end);
}

template <class T>
void StagedPath<T>::run_coupled(const StepContext<T>& c, const Phase& p, Block b) {
  const int s = accel_slot(p);
  const ParticleState<T> all{c.bodies.padded_size(), state_x(c, s, 0), state_x(c, s, 1),
                             state_x(c, s, 2),        state_v(c, s, 0), state_v(c, s, 1),
                             state_v(c, s, 2),        c.bodies.inv_mass()};
  const ParticleBlock<T> view = block_view(c, s, b, phase_time(c, p));
  if (coupled_.nbody) add_gravity(c, s, b);
  if (!coupled_.springs.empty()) add_springs(c, s, b);
  for (const auto& term : forces_.coupled_terms()) term->accumulate(all, view);
  add_forces(c, s, b);
}

template <class T>
void StagedPath<T>::add_gravity(const StepContext<T>& c, int s, Block b) {
  kernels::NBodyJob<T> job{};
  for (int d = 0; d < 3; ++d) job.x[d] = state_x(c, s, d), job.acc[d] = stage_a_[s][d].data();
  job.inv_mass = c.bodies.inv_mass();
  job.sources = c.bodies.padded_size();
  job.eps2 = coupled_.eps2;
  job.scale_G = c.accel_scale * T(coupled_.nbody->G);
  job.fast = coupled_.nbody->fast;
  table_.nbody(job, b.begin, b.end);
}

template <class T>
void StagedPath<T>::add_springs(const StepContext<T>& c, int s, Block b) {
  const T* x[3] = {state_x(c, s, 0), state_x(c, s, 1), state_x(c, s, 2)};
  const T* v[3] = {state_v(c, s, 0), state_v(c, s, 1), state_v(c, s, 2)};
  T* force[3] = {force_[0].data(), force_[1].data(), force_[2].data()};
  table_.springs(coupled_.springs.job(x, v, force), b.begin, b.end);
}

template <class T>
void StagedPath<T>::run_finish(const StepContext<T>& c, Block b) {
  // Positions first: they read the stage-0 velocities, which are the bodies' own.
  table_.combine(finish_jobs_[0], b.begin, b.end);
  table_.combine(finish_jobs_[1], b.begin, b.end);
  if (attempt_ != nullptr) block_error_[b.begin / kBlockBodies] = block_error(c, b);
}

template <class T>
std::array<kernels::CombineJob<T>, 2> StagedPath<T>::finish_jobs(const StepContext<T>& c) {
  auto body = arrays(c.bodies);
  kernels::CombineJob<T> x{}, v{};
  for (int d = 0; d < 3; ++d) {
    x.c.in[d] = x.c.out[d] = body.x[d];
    v.c.in[d] = v.c.out[d] = body.v[d];
  }
  const kernels::RowSum row = kernels::row_sum(method_.tableau.b);
  const int stages = method_.tableau.stages;
  x.c.set(row, stages, [&](int s) { return velocities(c, s); });
  v.c.set(row, stages, [&](int s) { return accelerations(s); });
  set_steps(c, row, x.c, v.c);
  return {x, v};
}

// The block's sum of squared weighted errors over its six components, e = h sum_s (b_s -
// b_hat_s) k_s (velocity stages for positions, accelerations, kept times sigma h, for
// velocities). y0 is the state kept by the attempt.
template <class T>
void StagedPath<T>::error_terms(const StepContext<T>& c, int field, int d, std::array<const T*, kMaxStages>& k,
                                std::array<double, kMaxStages>& w) const {
  const auto& t = method_.tableau;
  const double sigma = kernels::acceleration_scale(t);
  for (int s = 0; s < t.stages; ++s) {
    // A stage that reads the bodies' own velocities reads them as they were: the finish
    // has moved them on.
    k[s] = field == 1 ? accelerations(s)[d] : own_state(s) ? saved_[1][d].data() : velocities(c, s)[d];
    w[s] = (t.b[s] - t.b_hat[s]) * (field == 0 ? double(c.h) : 1 / sigma);
  }
}

template <class T>
double StagedPath<T>::block_error(const StepContext<T>& c, Block b) const {
  const auto body = arrays(c.bodies);
  double sum = 0;
  for (int field = 0; field < 2; ++field) {
    for (int d = 0; d < 3; ++d) {
      const T* y0 = saved_[field][d].data() + b.begin;
      const T* y1 = (field == 0 ? body.x[d] : body.v[d]) + b.begin;
      std::array<const T*, kMaxStages> k{};
      std::array<double, kMaxStages> w{};
      error_terms(c, field, d, k, w);
      for (int s = 0; s < method_.tableau.stages; ++s) k[s] += b.begin;
      // Real bodies only: padding stays at zero.
      const std::size_t n = std::min(b.end, c.bodies.size()) - std::min(b.begin, c.bodies.size());
      sum += error_squares(y0, y1, k.data(), w.data(), method_.tableau.stages, attempt_->rtol, attempt_->atol, n);
    }
  }
  return sum;
}

template <class T>
typename StagedPath<T>::WorstError StagedPath<T>::worst_error(const StepContext<T>& c, double rtol, double atol) const {
  WorstError worst;
  for (int field = 0; field < 2; ++field) {
    for (int d = 0; d < 3; ++d) {
      std::array<const T*, kMaxStages> k{};
      std::array<double, kMaxStages> w{};
      error_terms(c, field, d, k, w);
      const T* y0 = saved_[field][d].data();
      for (std::size_t i = 0; i < c.bodies.size(); ++i) {
        double e = 0;
        for (int s = 0; s < method_.tableau.stages; ++s) e += w[s] * double(k[s][i]);
        const double q = std::abs(e) / (atol + rtol * std::abs(double(y0[i])));
        // The first NaN error is the worst, and stays so.
        if (!std::isnan(worst.weighted) && !(q <= worst.weighted)) worst = {i, 3 * field + d, q};
      }
    }
  }
  return worst;
}

template <class T>
void StagedPath<T>::run_kick_drift(const Phase& p, Block b) {
  table_.combine(kick_drift_jobs_[p.index], b.begin, b.end);
}

template <class T>
kernels::CombineJob<T> StagedPath<T>::kick_drift_job(const StepContext<T>& c, int op) const {
  auto body = arrays(c.bodies);
  const bool kick = method_.scheme.ops[op].kind == OpKind::kick;
  kernels::CombineJob<T> job{};
  for (int d = 0; d < 3; ++d) job.c.in[d] = job.c.out[d] = kick ? body.v[d] : body.x[d];
  // One term of weight 1, the step the operation's weight times h.
  job.c.set(kernels::row_sum({1}), 1, [&](int) { return kick ? accelerations(0) : velocities(c, 0); });
  job.c.step = T(method_.scheme.ops[op].weight) * c.h;
  return job;
}

template class StagedPath<float>;
template class StagedPath<double>;

}  // namespace kinema
