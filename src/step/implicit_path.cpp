#include "step/implicit_path.hpp"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "kinema/error.hpp"

namespace kinema {

using kernels::kSpringSlice;

namespace {

// The relative residual a solve stops at when the options leave it to T: well below the
// error of a step, above what T can resolve.
template <class T>
double default_tolerance() {
  return std::is_same_v<T, float> ? 1e-5 : 1e-10;
}

}  // namespace

template <class T>
ImplicitPath<T>::ImplicitPath(const ForceModel<T>& forces, const Method& method, const kernels::KernelTable<T>& table,
                              const LoweredForces<T>& lowered, const StepperOptions& options)
    : method_(method),
      net_(lowered.coupled.springs),
      rates_(forces, euler, table, lowered.particle, lowered.coupled),
      tolerance_(options.implicit_tolerance > 0 ? options.implicit_tolerance : default_tolerance<T>()),
      max_iterations_(options.implicit_max_iterations) {}

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
  std::size_t arrays = 11 * 3 + 4 * 3 + 1;
  return arrays * capacity_ * sizeof(T) + (k_along_.size() * 5) * sizeof(T) + rates_.bytes();
}

template <class T>
void ImplicitPath<T>::step(const StepContext<T>& c) {
  reserve(c.bodies.padded_size());
  const std::size_t slots = net_.rest.size();
  if (k_along_.size() < slots) {  // the network is laid out before the first step
    for (auto& a : unit_) a.resize(slots);
    k_along_.resize(slots), k_across_.resize(slots);
  }
  gh_ = T(method_.rosenbrock.gamma * double(c.h));
  save_start(c);
  try {
    build_jacobian(c);
    for (int s = 0; s < method_.rosenbrock.stages; ++s) {
      evaluate_stage(c, s);
      solve_stage(c, s);
    }
    finish(c);
  } catch (...) {
    restore_start(c);
    throw;
  }
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
    const std::size_t stop = std::min(b.end, net_.covered);
    for (std::size_t slice = b.begin / kSpringSlice; slice * kSpringSlice < stop; ++slice) {
      // A set padded to fewer than kSpringSlice bodies past its last slice's first.
      const std::size_t lanes = std::min(kSpringSlice, b.end - slice * kSpringSlice);
      for (std::size_t e = net_.slice_offset[slice]; e < net_.slice_offset[slice + 1]; ++e) {
        for (std::size_t lane = 0; lane < lanes; ++lane) {
          const std::size_t i = slice * kSpringSlice + lane, at = e * kSpringSlice + lane;
          const std::size_t j = std::size_t(net_.neighbor[at]);
          T dx[3], length2 = 0;
          for (int d = 0; d < 3; ++d) dx[d] = x0_[d][j] - x0_[d][i], length2 += dx[d] * dx[d];
          const T length = std::sqrt(length2), k = net_.k[at];
          // Stretched: the geometric stiffness k (1 - rest / length) across the spring. Under
          // compression it would be negative: left out, so the matrix stays definite.
          const T across = length > 0 ? std::max(T(0), T(1) - std::max(net_.rest[at], T(0)) / length) : T(0);
          k_along_[at] = k * (T(1) - across), k_across_[at] = k * across;
          const T w = sc * net_.damping[at] + sk * k_along_[at];
          for (int d = 0; d < 3; ++d) {
            unit_[d][at] = length > 0 ? dx[d] / length : T(0);
            inv_diag_[d][i] -= w * unit_[d][at] * unit_[d][at] + sk * k_across_[at];
          }
        }
      }
    }
    for (std::size_t i = b.begin; i < b.end; ++i) {
      for (int d = 0; d < 3; ++d) inv_diag_[d][i] = mass_[i] == 0 ? T(0) : T(1) / inv_diag_[d][i];
    }
  });
}

// Slice by slice, the slice's own values and sums in local arrays and each entry's other
// ends gathered into one: loops over the lanes that the compiler can vectorize (the same
// operations in the same order per body as one at a time, so the same bits).
template <class T>
void ImplicitPath<T>::product(Block b, const T* const p[3], T* const out[3], T cm, T sc, T sk) const {
  for (std::size_t first = b.begin; first < b.end; first += kSpringSlice) {
    const std::size_t lanes = std::min(kSpringSlice, b.end - first);
    alignas(64) T own[3][kSpringSlice], sum[3][kSpringSlice], other[3][kSpringSlice];
    for (int d = 0; d < 3; ++d) {
      for (std::size_t l = 0; l < lanes; ++l) own[d][l] = p[d][first + l], sum[d][l] = cm * mass_[first + l] * own[d][l];
    }
    const std::size_t slice = first / kSpringSlice;
    const std::size_t entries_end = first < net_.covered ? net_.slice_offset[slice + 1] : 0;
    for (std::size_t e = first < net_.covered ? net_.slice_offset[slice] : 0; e < entries_end; ++e) {
      // An empty slot joins a body to itself with no stiffness: it adds nothing.
      const std::size_t at = e * kSpringSlice;
      for (std::size_t l = 0; l < lanes; ++l) {
        const std::size_t j = std::size_t(net_.neighbor[at + l]);
        for (int d = 0; d < 3; ++d) other[d][l] = p[d][j];
      }
      const T *ux = unit_[0].data() + at, *uy = unit_[1].data() + at, *uz = unit_[2].data() + at;
      const T *damping = net_.damping.data() + at, *along_k = k_along_.data() + at, *across_k = k_across_.data() + at;
      for (std::size_t l = 0; l < lanes; ++l) {
        const T dx = other[0][l] - own[0][l], dy = other[1][l] - own[1][l], dz = other[2][l] - own[2][l];
        const T along = ux[l] * dx + uy[l] * dy + uz[l] * dz;
        const T s = (sc * damping[l] + sk * along_k[l]) * along, across = sk * across_k[l];
        sum[0][l] += s * ux[l] + across * dx;
        sum[1][l] += s * uy[l] + across * dy;
        sum[2][l] += s * uz[l] + across * dz;
      }
    }
    for (int d = 0; d < 3; ++d) {
      for (std::size_t l = 0; l < lanes; ++l) out[d][first + l] = mass_[first + l] == 0 ? T(0) : sum[d][l];
    }
  }
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
    product(k, rx, kr, T(0), T(0), T(1));
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
  const T sc = -gh_, sk = -gh_ * gh_;
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
  ++stats_.solves;
  const double goal = tolerance_ * tolerance_ * bb;
  int iterations = 0;
  for (double rr = bb; rr > goal; ++iterations) {
    if (iterations == max_iterations_) {
      ++stats_.unconverged;
      break;
    }
    if (c.stop != nullptr && (*c.stop)()) throw Stopped();
    const double pq = sum_blocks(c, [&](Block b, double* sums) {
      product(b, p, q, T(1), sc, sk);
      for (std::size_t i = b.begin; i < b.end; ++i) {
        for (int d = 0; d < 3; ++d) sums[0] += double(p_[d][i]) * double(q_[d][i]);
      }
    })[0];
    const T alpha = T(rz / pq);
    const auto [rz_next, rr_next] = sum_blocks(c, [&](Block b, double* sums) {
      for (std::size_t i = b.begin; i < b.end; ++i) {
        for (int d = 0; d < 3; ++d) {
          x[d][i] += alpha * p_[d][i], r_[d][i] -= alpha * q_[d][i], z_[d][i] = inv_diag_[d][i] * r_[d][i];
          sums[0] += double(r_[d][i]) * double(z_[d][i]), sums[1] += double(r_[d][i]) * double(r_[d][i]);
        }
      }
    });
    const T beta = T(rz_next / rz);
    rz = rz_next, rr = rr_next;
    if (rr <= goal) {
      ++iterations;
      break;
    }
    for_each_block(c.workers, c.bodies.padded_size(), [&](Block b) {
      for (std::size_t i = b.begin; i < b.end; ++i) {
        for (int d = 0; d < 3; ++d) p_[d][i] = z_[d][i] + beta * p_[d][i];
      }
    });
  }
  stats_.iterations += std::uint64_t(iterations);
  stats_.max_iterations = std::max(stats_.max_iterations, iterations);
}

template class ImplicitPath<float>;
template class ImplicitPath<double>;

}  // namespace kinema
