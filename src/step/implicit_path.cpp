#include "step/implicit_path.hpp"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "core/text.hpp"
#include "kinema/error.hpp"

namespace kinema {

using kernels::kSpringSlice;

template <class T>
ImplicitPath<T>::ImplicitPath(const ForceModel<T>& forces, const Method& method, const kernels::KernelTable<T>& table,
                              const LoweredForces<T>& lowered, const StepperOptions& options)
    : method_(method),
      net_(lowered.coupled.springs),
      rates_(forces, euler, table, lowered.particle, lowered.coupled),
      tolerance_(options.implicit_tolerance > 0 ? options.implicit_tolerance : kDefaultImplicitTolerance<T>),
      max_iterations_(options.implicit_max_iterations),
      preconditioner_(options.implicit_preconditioner) {}

template <class T>
void ImplicitPath<T>::reserve(std::size_t padded) {
  rates_.reserve(padded);
  if (padded <= capacity_) return;
  for (Vec3s* v : {&x0_, &v0_, &rx_, &rhs_, &r_, &z_, &p_, &q_, &inv_diag_}) {
    for (auto& a : *v) a.resize(padded);
  }
  for (int s = 0; s < kMaxRosenbrockStages; ++s) {
    for (int d = 0; d < 3; ++d) kx_[s][d].resize(padded), kv_[s][d].resize(padded);
  }
  mass_.resize(padded);
  for (auto& sums : block_sums_) sums.resize(block_count(padded));
  capacity_ = padded;
}

template <class T>
std::size_t ImplicitPath<T>::bytes() const {
  const std::size_t arrays = 9 * 3 + 4 * 3 + 1;  // x0 .. inv_diag, the stages' k, the masses
  return arrays * capacity_ * sizeof(T) + (k_along_.size() * 7) * sizeof(T) + rates_.bytes() + multigrid_.bytes();
}

template <class T>
void ImplicitPath<T>::step(const StepContext<T>& c) {
  reserve(c.bodies.padded_size());
  const std::size_t slots = net_.rest.size();
  if (k_along_.size() < slots) {  // the network is laid out before the first step
    for (auto& a : unit_) a.resize(slots);
    for (AlignedArray<T>* a : {&k_along_, &k_across_, &a_along_, &a_across_}) a->resize(slots);
  }
  use_multigrid_ = takes_multigrid(preconditioner_, net_.covered);
  if (use_multigrid_ && !multigrid_.built_for(net_)) multigrid_.build(net_);
  gh_ = T(method_.rosenbrock.gamma * double(c.h));
  save_start(c);
  step_stats_ = {};
  try {
    build_jacobian(c);
    if (use_multigrid_) {
      multigrid_.set_operator(c.workers, {mass_.data(),
                                          {unit_[0].data(), unit_[1].data(), unit_[2].data()},
                                          a_along_.data(),
                                          a_across_.data()},
                              c.bodies.padded_size());
    }
    for (int s = 0; s < method_.rosenbrock.stages; ++s) {
      evaluate_stage(c, s);
      solve_stage(c, s);
    }
    finish(c);
  } catch (...) {
    restore_start(c);
    throw;
  }
  // A step taken back (a throw, a stop) counts nothing; a step the guard takes again, twice.
  stats_.solves += step_stats_.solves, stats_.iterations += step_stats_.iterations;
  stats_.unconverged += step_stats_.unconverged;
  stats_.max_iterations = std::max(stats_.max_iterations, step_stats_.max_iterations);
}

template <class T>
void ImplicitPath<T>::save_start(const StepContext<T>& c) {
  ParticleSet<T>& b = c.bodies;
  const T* const x[3] = {b.px(), b.py(), b.pz()};
  const T* const v[3] = {b.vx(), b.vy(), b.vz()};
  const T* w = b.inv_mass();
  for_each_block(c.workers, b.padded_size(), [&](Block k) {
    for (int d = 0; d < 3; ++d) {
      std::copy(x[d] + k.begin, x[d] + k.end, x0_[d].data() + k.begin);
      std::copy(v[d] + k.begin, v[d] + k.end, v0_[d].data() + k.begin);
    }
    for (std::size_t i = k.begin; i < k.end; ++i) mass_[i] = w[i] == 0 ? T(0) : T(1) / w[i];
  });
}

template <class T>
void ImplicitPath<T>::restore_start(const StepContext<T>& c) {
  ParticleSet<T>& b = c.bodies;
  T* const x[3] = {b.px(), b.py(), b.pz()};
  T* const v[3] = {b.vx(), b.vy(), b.vz()};
  for (int d = 0; d < 3; ++d) {
    std::copy(x0_[d].data(), x0_[d].data() + b.padded_size(), x[d]);
    std::copy(v0_[d].data(), v0_[d].data() + b.padded_size(), v[d]);
  }
}

// Each slot's direction and stiffnesses at the step's start, and each body's diagonal of
// the system's matrix, which the preconditioner divides by.
template <class T>
void ImplicitPath<T>::build_jacobian(const StepContext<T>& c) {
  const T sc = -gh_, sk = -gh_ * gh_;
  for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) {
    for (std::size_t i = b.begin; i < b.end; ++i) {
      for (int d = 0; d < 3; ++d) inv_diag_[d][i] = mass_[i];
    }
    const kernels::JacobianJob<T> job{{x0_[0].data(), x0_[1].data(), x0_[2].data()},
                                      net_.covered,
                                      net_.slice_offset.data(),
                                      net_.neighbor.data(),
                                      net_.rest.data(),
                                      net_.k.data(),
                                      net_.damping.data(),
                                      sc,
                                      sk,
                                      {unit_[0].data(), unit_[1].data(), unit_[2].data()},
                                      k_along_.data(),
                                      k_across_.data(),
                                      a_along_.data(),
                                      a_across_.data(),
                                      {inv_diag_[0].data(), inv_diag_[1].data(), inv_diag_[2].data()}};
    kernels::spring_jacobian(job, b.begin, b.end);
    for (std::size_t i = b.begin; i < b.end; ++i) {
      for (int d = 0; d < 3; ++d) inv_diag_[d][i] = mass_[i] == 0 ? T(0) : T(1) / inv_diag_[d][i];
    }
  });
}

template <class T>
double ImplicitPath<T>::product(Block b, const T* const p[3], T* const out[3], T cm, const T* along,
                                const T* across) const {
  const kernels::SpringProductJob<T> job{{p[0], p[1], p[2]},
                                         {out[0], out[1], out[2]},
                                         {nullptr, nullptr, nullptr},
                                         mass_.data(),
                                         net_.covered,
                                         net_.slice_offset.data(),
                                         net_.neighbor.data(),
                                         net_.contiguous.data(),
                                         {unit_[0].data(), unit_[1].data(), unit_[2].data()},
                                         along,
                                         across,
                                         cm};
  return kernels::spring_product(job, b.begin, b.end);
}

// The stage's state (the step's start moved by the earlier stages), the forces there, and
// the system's right side M r_v + gamma h K r_x.
template <class T>
void ImplicitPath<T>::evaluate_stage(const StepContext<T>& c, int s) {
  const RosenbrockScheme& r = method_.rosenbrock;
  ParticleSet<T>& b = c.bodies;
  T* const x[3] = {b.px(), b.py(), b.pz()};
  T* const v[3] = {b.vx(), b.vy(), b.vz()};
  const T h = c.h;
  if (s > 0) {
    for_each_block(c.workers, b.padded_size(), [&](Block k) {
      for (std::size_t i = k.begin; i < k.end; ++i) {
        for (int d = 0; d < 3; ++d) {
          T dx = 0, dv = 0;
          for (int j = 0; j < s; ++j) dx += T(r.a[s][j]) * kx_[j][d][i], dv += T(r.a[s][j]) * kv_[j][d][i];
          x[d][i] = x0_[d][i] + h * dx, v[d][i] = v0_[d][i] + h * dv;
        }
      }
    });
  }
  rates_.evaluate_first_stage({b, T(1), T(1), c.t0 + r.time[s] * double(h), c.workers, c.stop});
  const std::array<const T*, 3> a = rates_.first_stage();
  for_each_block(c.workers, b.padded_size(), [&](Block k) {
    for (std::size_t i = k.begin; i < k.end; ++i) {
      for (int d = 0; d < 3; ++d) {
        T ex = v[d][i], ev = a[d][i];
        for (int j = 0; j < s; ++j) ex += T(r.c[s][j]) * kx_[j][d][i], ev += T(r.c[s][j]) * kv_[j][d][i];
        rx_[d][i] = ex, rhs_[d][i] = ev;
      }
    }
  });
  T* const kr[3] = {q_[0].data(), q_[1].data(), q_[2].data()};
  const T* const rx[3] = {rx_[0].data(), rx_[1].data(), rx_[2].data()};
  for_each_block(c.workers, b.padded_size(), [&](Block k) {
    product(k, rx, kr, T(0), k_along_.data(), k_across_.data());
    for (std::size_t i = k.begin; i < k.end; ++i) {
      for (int d = 0; d < 3; ++d) rhs_[d][i] = mass_[i] * rhs_[d][i] + gh_ * q_[d][i];
    }
  });
}

template <class T>
void ImplicitPath<T>::solve_stage(const StepContext<T>& c, int s) {
  conjugate_gradients(c, kv_[s]);
  for_each_block(c.workers, c.bodies.padded_size(), [&](Block k) {
    for (std::size_t i = k.begin; i < k.end; ++i) {
      for (int d = 0; d < 3; ++d) kx_[s][d][i] = rx_[d][i] + gh_ * kv_[s][d][i];
    }
  });
}

template <class T>
void ImplicitPath<T>::finish(const StepContext<T>& c) {
  const RosenbrockScheme& r = method_.rosenbrock;
  ParticleSet<T>& b = c.bodies;
  T* const x[3] = {b.px(), b.py(), b.pz()};
  T* const v[3] = {b.vx(), b.vy(), b.vz()};
  const T h = c.h;
  for_each_block(c.workers, b.padded_size(), [&](Block k) {
    for (std::size_t i = k.begin; i < k.end; ++i) {
      for (int d = 0; d < 3; ++d) {
        T dx = 0, dv = 0;
        for (int s = 0; s < r.stages; ++s) dx += T(r.m[s]) * kx_[s][d][i], dv += T(r.m[s]) * kv_[s][d][i];
        x[d][i] = x0_[d][i] + h * dx, v[d][i] = v0_[d][i] + h * dv;
      }
    }
  });
}

template <class T>
template <class Pass>
std::array<double, 2> ImplicitPath<T>::sum_blocks(const StepContext<T>& c, Pass&& pass) {
  const std::size_t n = c.bodies.padded_size();
  for_each_block(c.workers, n, [&](Block b) {
    double sums[2] = {0, 0};
    pass(b, sums);
    const std::size_t i = b.begin / kBlockBodies;
    block_sums_[0][i] = sums[0], block_sums_[1][i] = sums[1];
  });
  std::array<double, 2> total{0, 0};
  for (std::size_t i = 0; i < block_count(n); ++i) total[0] += block_sums_[0][i], total[1] += block_sums_[1][i];
  return total;
}

// Preconditioned conjugate gradients from x = 0 on A x = rhs_, A = M - gamma h D - (gamma h)^2 K,
// until |r| <= tolerance |rhs| or the iteration cap.
template <class T>
void ImplicitPath<T>::conjugate_gradients(const StepContext<T>& c, Vec3s& x) {
  T* const p[3] = {p_[0].data(), p_[1].data(), p_[2].data()};
  T* const q[3] = {q_[0].data(), q_[1].data(), q_[2].data()};
  auto [rz, bb] = sum_blocks(c, [&](Block b, double* sums) {
    for (std::size_t i = b.begin; i < b.end; ++i) {
      for (int d = 0; d < 3; ++d) {
        x[d][i] = 0, r_[d][i] = rhs_[d][i], z_[d][i] = inv_diag_[d][i] * r_[d][i], p_[d][i] = z_[d][i];
        sums[0] += double(r_[d][i]) * double(z_[d][i]), sums[1] += double(r_[d][i]) * double(r_[d][i]);
      }
    }
  });
  ++step_stats_.solves;
  if (!std::isfinite(bb)) {
    // From finite rates and state, a right side that is not finite overflowed T: refused.
    // Else what was not finite goes on to the state; with no springs M k_v = r is solved
    // (what overflows there is the explicit forces' blow-up, as under an explicit method).
    const std::size_t n = c.bodies.padded_size();
    const bool springs = net_.rest.size() > 0;
    const bool inputs_finite = all_finite(rates_.first_stage().data(), n) && all_finite(rx_, n);
    const bool right_side_finite = all_finite(rhs_, n);
    if (springs && inputs_finite && !right_side_finite) overflows();
    if (!right_side_finite) ++step_stats_.unconverged;
    if (!right_side_finite || !springs) return take_preconditioned(c, x);
    overflows();
  }
  if (use_multigrid_) {
    rz = precondition(c);
    for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) {
      for (int d = 0; d < 3; ++d) std::copy(z_[d].data() + b.begin, z_[d].data() + b.end, p[d] + b.begin);
    });
  }
  const double goal = tolerance_ * tolerance_ * bb;
  int iterations = 0;
  for (double rr = bb; rr > goal; ++iterations) {
    if (iterations == max_iterations_) {
      ++step_stats_.unconverged;
      break;
    }
    if (c.stop != nullptr && (*c.stop)()) throw Stopped();
    const double pq = sum_blocks(c, [&](Block b, double* sums) {
      sums[0] = product(b, p, q, T(1), a_along_.data(), a_across_.data());
    })[0];
    if (!std::isfinite(pq)) overflows();
    // Under multigrid the V-cycle makes z (and r . z): the update leaves them.
    T* const z = use_multigrid_ ? nullptr : z_[0].data();
    const kernels::CgUpdateJob<T> update{{x[0].data(), x[1].data(), x[2].data()},
                                         {r_[0].data(), r_[1].data(), r_[2].data()},
                                         {z, z ? z_[1].data() : nullptr, z ? z_[2].data() : nullptr},
                                         {p[0], p[1], p[2]},
                                         {q[0], q[1], q[2]},
                                         {inv_diag_[0].data(), inv_diag_[1].data(), inv_diag_[2].data()},
                                         T(rz / pq)};
    auto [rz_next, rr_next] = sum_blocks(c, [&](Block b, double* sums) { kernels::cg_update(update, b.begin, b.end, sums); });
    if (!std::isfinite(rr_next)) overflows();
    rr = rr_next;
    if (rr <= goal) {
      ++iterations;
      break;
    }
    if (use_multigrid_) rz_next = precondition(c);
    const T beta = T(rz_next / rz);
    rz = rz_next;
    const kernels::CgDirectionJob<T> direction{{p[0], p[1], p[2]}, {z_[0].data(), z_[1].data(), z_[2].data()}, beta};
    for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) { kernels::cg_direction(direction, b.begin, b.end); });
  }
  step_stats_.iterations += std::uint64_t(iterations);
  step_stats_.max_iterations = std::max(step_stats_.max_iterations, iterations);
}

template <class T>
double ImplicitPath<T>::precondition(const StepContext<T>& c) {
  const T* const r[3] = {r_[0].data(), r_[1].data(), r_[2].data()};
  T* const z[3] = {z_[0].data(), z_[1].data(), z_[2].data()};
  return multigrid_.apply(c.workers, r, z);
}

// A right side that is not finite (a force or the state that was not): no iteration could
// converge, and none is tried. Each body's answer is the preconditioner's, so what is not
// finite reaches the state, where the finiteness guard (or the caller) sees it. (With no
// springs the preconditioner's answer is the solution.)
template <class T>
void ImplicitPath<T>::take_preconditioned(const StepContext<T>& c, Vec3s& x) {
  for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) {
    for (std::size_t i = b.begin; i < b.end; ++i) {
      for (int d = 0; d < 3; ++d) x[d][i] = z_[d][i];
    }
  });
}

template <class T>
void ImplicitPath<T>::overflows() const {
  throw SolveOverflowError(std::string(method_.name) + ": a linear solve's sums overflow " + type_name<T>() + " or are not finite" +
              " (the springs' stiffness times the step squared, over the masses, is too large for this precision, "
              "or the state is blowing up); the step is not taken");
}

template <class T>
bool ImplicitPath<T>::all_finite(const T* const* v, std::size_t n) {
  for (int d = 0; d < 3; ++d) {
    if (!std::all_of(v[d], v[d] + n, [](T y) { return std::isfinite(y); })) return false;
  }
  return true;
}

template <class T>
bool ImplicitPath<T>::all_finite(const Vec3s& v, std::size_t n) {
  const T* const p[3] = {v[0].data(), v[1].data(), v[2].data()};
  return all_finite(p, n);
}

template class ImplicitPath<float>;
template class ImplicitPath<double>;

}  // namespace kinema
