// The implicit path's passes of implicit_kernels.hpp, cloned per instruction set with the
// same operations in each (the library builds with -ffp-contract=off: no fused multiply-add
// is formed, so every clone rounds as the baseline one does).
#include "kernels/implicit_kernels.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <type_traits>

#include "kernels/cloned.hpp"
#include "kernels/kernels.hpp"

namespace kinema::kernels {
namespace {

constexpr std::size_t kLanes = kSpringSlice;

// The other ends of one entry's lanes: consecutive bodies (read where they are), or gathered
// into `gathered` by the slots' neighbours. A masked run (some lanes' slots empty) is
// gathered too: an empty slot's neighbour is its body, whose value is the one the run's
// layout gives it, and a gather vectorizes where a per-lane choice did not.
template <bool Full, class T>
[[gnu::always_inline]] inline void other_ends(const SpringProductJob<T>& job, std::size_t entry, std::size_t lanes,
                                              T (&gathered)[3][kLanes], const T* (&other)[3]) {
  const std::size_t n = Full ? kLanes : lanes;
  const std::int32_t code = job.contiguous[entry];
  if (code >= 0) {
    for (int d = 0; d < 3; ++d) other[d] = job.p[d] + code;
    return;
  }
  const std::int32_t* __restrict neighbor = job.neighbor + entry * kLanes;
  for (int d = 0; d < 3; ++d) {
    const T* __restrict p = job.p[d];
    T* __restrict g = gathered[d];
    for (std::size_t l = 0; l < n; ++l) g[l] = p[std::size_t(neighbor[l])];
    other[d] = gathered[d];
  }
}

// Through restrict locals: the sums are stores the compiler could not otherwise keep apart
// from the job's pointers, and it would load them again for every lane.
template <bool Full, class T>
[[gnu::always_inline]] inline void add_entry(const SpringProductJob<T>& job, std::size_t entry, std::size_t lanes,
                                             const T (&own)[3][kLanes], const T* const (&other)[3],
                                             T (&sum)[3][kLanes]) {
  const std::size_t n = Full ? kLanes : lanes;
  const std::size_t at = entry * kLanes;
  const T *__restrict ux = job.unit[0] + at, *__restrict uy = job.unit[1] + at, *__restrict uz = job.unit[2] + at;
  const T *__restrict along_w = job.along + at, *__restrict across_w = job.across + at;
  const T *__restrict ox = other[0], *__restrict oy = other[1], *__restrict oz = other[2];
  // The slots' arrays are five streams beside the vectors' seven: the hardware prefetcher
  // alone leaves their misses exposed. A few entries ahead (past the end is harmless).
  constexpr std::size_t ahead = 32 * kLanes;
  for (const T* a : {ux, uy, uz, along_w, across_w}) __builtin_prefetch(a + ahead);
  T *__restrict sx = sum[0], *__restrict sy = sum[1], *__restrict sz = sum[2];
  for (std::size_t l = 0; l < n; ++l) {
    const T dx = ox[l] - own[0][l], dy = oy[l] - own[1][l], dz = oz[l] - own[2][l];
    const T s = along_w[l] * (ux[l] * dx + uy[l] * dy + uz[l] * dz), across = across_w[l];
    sx[l] += s * ux[l] + across * dx;
    sy[l] += s * uy[l] + across * dy;
    sz[l] += s * uz[l] + across * dz;
  }
}

// One slice: its own values and sums in local arrays; p . out to a running sum per lane.
template <bool Full, class T>
[[gnu::always_inline]] inline void product_slice(const SpringProductJob<T>& job, std::size_t first, std::size_t lanes,
                                                 double (&dots)[kLanes]) {
  const std::size_t n = Full ? kLanes : lanes;
  alignas(64) T own[3][kLanes], sum[3][kLanes], gathered[3][kLanes];
  for (int d = 0; d < 3; ++d) {
    for (std::size_t l = 0; l < n; ++l) own[d][l] = job.p[d][first + l], sum[d][l] = job.cm * job.mass[first + l] * own[d][l];
  }
  if (first < job.covered) {
    const std::size_t slice = first / kLanes;
    for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
      const T* other[3];
      other_ends<Full>(job, e, lanes, gathered, other);
      add_entry<Full>(job, e, lanes, own, other, sum);
    }
  }
  // Fixed bodies' out is 0: selected on the bits (a mass is never negative, so it is 0 when
  // its bits past the sign are), which vectorizes where a float compare and branch did not.
  using Bits = std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>;
  const T* __restrict mass = job.mass + first;
  for (int d = 0; d < 3; ++d) {
    T* __restrict out = job.out[d] + first;
    const T *__restrict own_d = own[d], *__restrict sum_d = sum[d];
    for (std::size_t l = 0; l < n; ++l) {
      const Bits keep = std::bit_cast<Bits>(mass[l]) << 1 == 0 ? Bits(0) : ~Bits(0);
      const T value = std::bit_cast<T>(std::bit_cast<Bits>(sum_d[l]) & keep);
      out[l] = value;
      dots[l] += double(own_d[l]) * double(value);
    }
  }
}

// Slice by slice (a set padded to less than a slice ends in a partial one); the lanes' sums
// added in lane order at the end.
template <class T>
[[gnu::always_inline]] inline double product_of(const SpringProductJob<T>& job, std::size_t begin, std::size_t end) {
  double dots[kLanes] = {};
  std::size_t first = begin;
  for (; first + kLanes <= end; first += kLanes) product_slice<true>(job, first, kLanes, dots);
  if (first < end) product_slice<false>(job, first, end - first, dots);
  double total = 0;
  for (double x : dots) total += x;
  return total;
}

// One slice's lanes of one array, through restrict locals: stores through the job's pointers
// could otherwise alias alpha and each other, and the loop would not vectorize.
template <bool Full, class T>
[[gnu::always_inline]] inline void update_lanes(T* __restrict x, T* __restrict r, T* __restrict z,
                                                const T* __restrict p, const T* __restrict q,
                                                const T* __restrict inv_diag, T alpha, std::size_t lanes,
                                                double (&rz)[kLanes], double (&rr)[kLanes]) {
  const std::size_t n = Full ? kLanes : lanes;
  for (std::size_t l = 0; l < n; ++l) {
    x[l] += alpha * p[l];
    const T rl = r[l] - alpha * q[l], zl = inv_diag[l] * rl;
    r[l] = rl, z[l] = zl;
    rz[l] += double(rl) * double(zl), rr[l] += double(rl) * double(rl);
  }
}

template <class T>
[[gnu::always_inline]] inline void update_of(const CgUpdateJob<T>& job, std::size_t begin, std::size_t end,
                                             double sums[2]) {
  double rz[kLanes] = {}, rr[kLanes] = {};
  const T alpha = job.alpha;
  for (std::size_t first = begin; first < end; first += kLanes) {
    const std::size_t lanes = std::min(kLanes, end - first);
    for (int d = 0; d < 3; ++d) {
      T *x = job.x[d] + first, *r = job.r[d] + first, *z = job.z[d] + first;
      const T *p = job.p[d] + first, *q = job.q[d] + first, *inv_diag = job.inv_diag[d] + first;
      if (lanes == kLanes) {
        update_lanes<true>(x, r, z, p, q, inv_diag, alpha, lanes, rz, rr);
      } else {
        update_lanes<false>(x, r, z, p, q, inv_diag, alpha, lanes, rz, rr);
      }
    }
  }
  for (std::size_t l = 0; l < kLanes; ++l) sums[0] += rz[l], sums[1] += rr[l];
}

template <class T>
[[gnu::always_inline]] inline void direction_of(const CgDirectionJob<T>& job, std::size_t begin, std::size_t end) {
  const T beta = job.beta;
  for (int d = 0; d < 3; ++d) {
    T* __restrict p = job.p[d];
    const T* __restrict z = job.z[d];
    for (std::size_t i = begin; i < end; ++i) p[i] = z[i] + beta * p[i];
  }
}

template <class T>
[[gnu::always_inline]] inline void jacobian_entry(const JacobianJob<T>& job, std::size_t first, std::size_t entry,
                                                  std::size_t lanes) {
  const std::size_t at0 = entry * kLanes;
  const std::int32_t* __restrict neighbor = job.neighbor + at0;
  const T *__restrict x = job.x[0], *__restrict y = job.x[1], *__restrict z = job.x[2];
  const T *__restrict rest = job.rest + at0, *__restrict kk = job.k + at0, *__restrict damping = job.damping + at0;
  T *__restrict ux = job.unit[0] + at0, *__restrict uy = job.unit[1] + at0, *__restrict uz = job.unit[2] + at0;
  T *__restrict k_along = job.k_along + at0, *__restrict k_across = job.k_across + at0;
  T *__restrict a_along = job.a_along + at0, *__restrict a_across = job.a_across + at0;
  T *__restrict dx_ = job.diag[0] + first, *__restrict dy_ = job.diag[1] + first, *__restrict dz_ = job.diag[2] + first;
  for (std::size_t l = 0; l < lanes; ++l) {
    const std::size_t i = first + l, j = std::size_t(neighbor[l]);
    const T dx = x[j] - x[i], dy = y[j] - y[i], dz = z[j] - z[i];
    const T length2 = ((T(0) + dx * dx) + dy * dy) + dz * dz;
    // A k of -0 counts as +0: no zero's sign in the products hangs on how k was written.
    const T length = std::sqrt(length2), k = kk[l] + T(0);
    // Stretched: the geometric stiffness k (1 - rest / length) across the spring. Under
    // compression it would be negative: left out, so the matrix stays definite.
    const T r = rest[l] < T(0) ? T(0) : rest[l], g = T(1) - r / length;
    const T across = length > 0 ? (g > T(0) ? g : T(0)) : T(0);
    const T along_k = k * (T(1) - across), across_k = k * across;
    k_along[l] = along_k, k_across[l] = across_k;
    const T w = job.sc * damping[l] + job.sk * along_k, wa = job.sk * across_k;
    a_along[l] = w, a_across[l] = wa;
    const T u0 = length > 0 ? dx / length : T(0), u1 = length > 0 ? dy / length : T(0), u2 = length > 0 ? dz / length : T(0);
    ux[l] = u0, uy[l] = u1, uz[l] = u2;
    dx_[l] -= w * u0 * u0 + wa, dy_[l] -= w * u1 * u1 + wa, dz_[l] -= w * u2 * u2 + wa;
  }
}

template <class T>
[[gnu::always_inline]] inline void jacobian_of(const JacobianJob<T>& job, std::size_t begin, std::size_t end) {
  const std::size_t stop = std::min(end, job.covered);
  for (std::size_t slice = begin / kLanes; slice * kLanes < stop; ++slice) {
    // A set padded to fewer than kLanes bodies past its last slice's first.
    const std::size_t lanes = std::min(kLanes, end - slice * kLanes);
    for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
      if (lanes == kLanes) {
        jacobian_entry(job, slice * kLanes, e, kLanes);
      } else {
        jacobian_entry(job, slice * kLanes, e, lanes);
      }
    }
  }
}

template <class T>
[[gnu::always_inline]] inline void smoother_slice(const SmootherJob<T>& job, std::size_t first, std::size_t lanes) {
  double g[6][kLanes];
  for (std::size_t l = 0; l < kLanes; ++l) {
    const double m = l < lanes ? double(job.mass[first + l]) : 0.0;
    g[0][l] = m, g[1][l] = m, g[2][l] = m, g[3][l] = 0, g[4][l] = 0, g[5][l] = 0;
  }
  if (first < job.covered) {
    const std::size_t slice = first / kLanes;
    for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
      const std::size_t at = e * kLanes;
      const T *__restrict ux = job.unit[0] + at, *__restrict uy = job.unit[1] + at, *__restrict uz = job.unit[2] + at;
      const T *__restrict along = job.along + at, *__restrict across = job.across + at;
      for (std::size_t l = 0; l < kLanes; ++l) {  // an empty slot's weights are 0
        const double w = -double(along[l]), a = -double(across[l]);
        const double u0 = double(ux[l]), u1 = double(uy[l]), u2 = double(uz[l]);
        g[0][l] += w * u0 * u0 + a, g[1][l] += w * u1 * u1 + a, g[2][l] += w * u2 * u2 + a;
        g[3][l] += w * u0 * u1, g[4][l] += w * u0 * u2, g[5][l] += w * u1 * u2;
      }
    }
  }
  for (std::size_t l = 0; l < lanes; ++l) {
    const double a = g[0][l], b = g[1][l], c = g[2][l], d = g[3][l], e = g[4][l], f = g[5][l];
    const double cof[6] = {b * c - f * f, a * c - e * e, a * b - d * d, e * f - d * c, d * f - e * b, d * e - a * f};
    const double det = a * cof[0] + d * cof[3] + e * cof[4];
    const bool definite = det > 0 && det < HUGE_VAL && a > 0 && job.mass[first + l] != T(0);
    for (int k = 0; k < 6; ++k) job.block[k][first + l] = definite ? T(job.scale * (cof[k] / det)) : T(0);
  }
}

template <class T>
[[gnu::always_inline]] inline void smoother_of(const SmootherJob<T>& job, std::size_t begin, std::size_t end) {
  for (std::size_t first = begin; first < end; first += kLanes) smoother_slice(job, first, std::min(kLanes, end - first));
}

template <class T>
[[gnu::always_inline]] inline void block_smooth_of(const BlockSmoothJob<T>& job, std::size_t begin, std::size_t end) {
  const T *__restrict xx = job.block[0], *__restrict yy = job.block[1], *__restrict zz = job.block[2];
  const T *__restrict xy = job.block[3], *__restrict xz = job.block[4], *__restrict yz = job.block[5];
  const T *__restrict x = job.in[0], *__restrict y = job.in[1], *__restrict z = job.in[2];
  T *__restrict ox = job.out[0], *__restrict oy = job.out[1], *__restrict oz = job.out[2];
  if (job.base[0] == nullptr) {
    for (std::size_t i = begin; i < end; ++i) {
      ox[i] = xx[i] * x[i] + xy[i] * y[i] + xz[i] * z[i];
      oy[i] = xy[i] * x[i] + yy[i] * y[i] + yz[i] * z[i];
      oz[i] = xz[i] * x[i] + yz[i] * y[i] + zz[i] * z[i];
    }
    return;
  }
  const T *__restrict bx = job.base[0], *__restrict by = job.base[1], *__restrict bz = job.base[2];
  for (std::size_t i = begin; i < end; ++i) {
    ox[i] = bx[i] + (xx[i] * x[i] + xy[i] * y[i] + xz[i] * z[i]);
    oy[i] = by[i] + (xy[i] * x[i] + yy[i] * y[i] + yz[i] * z[i]);
    oz[i] = bz[i] + (xz[i] * x[i] + yz[i] * y[i] + zz[i] * z[i]);
  }
}

template <class T>
[[gnu::always_inline]] inline void prolong_of(const ProlongJob<T>& job, std::size_t begin, std::size_t end) {
  const std::int32_t* __restrict node = job.node;
  for (int d = 0; d < 3; ++d) {
    const T* __restrict values = job.values[d];
    T* __restrict out = job.out[d];
    for (std::size_t i = begin; i < end; ++i) out[i] += values[node[i]];
  }
}

template <class T>
[[gnu::always_inline]] inline void subtract_of(const T* const r[3], T* const out[3], std::size_t begin, std::size_t end) {
  for (int d = 0; d < 3; ++d) {
    const T* __restrict from = r[d];
    T* __restrict to = out[d];
    for (std::size_t i = begin; i < end; ++i) to[i] = from[i] - to[i];
  }
}

template <class T>
[[gnu::always_inline]] inline double dot_of(const T* const a[3], const T* const b[3], std::size_t begin, std::size_t end) {
  double sums[kLanes] = {};
  for (int d = 0; d < 3; ++d) {
    const T *__restrict x = a[d], *__restrict y = b[d];
    std::size_t first = begin;
    for (; first + kLanes <= end; first += kLanes) {
      for (std::size_t l = 0; l < kLanes; ++l) sums[l] += double(x[first + l]) * double(y[first + l]);
    }
    for (std::size_t l = 0; first + l < end; ++l) sums[l] += double(x[first + l]) * double(y[first + l]);
  }
  double total = 0;
  for (double s : sums) total += s;
  return total;
}

}  // namespace

KINEMA_CLONED void spring_jacobian(const JacobianJob<float>& job, std::size_t begin, std::size_t end) {
  jacobian_of(job, begin, end);
}
KINEMA_CLONED void spring_jacobian(const JacobianJob<double>& job, std::size_t begin, std::size_t end) {
  jacobian_of(job, begin, end);
}
KINEMA_CLONED void smoother_blocks(const SmootherJob<float>& job, std::size_t begin, std::size_t end) {
  smoother_of(job, begin, end);
}
KINEMA_CLONED void smoother_blocks(const SmootherJob<double>& job, std::size_t begin, std::size_t end) {
  smoother_of(job, begin, end);
}
KINEMA_CLONED void block_smooth(const BlockSmoothJob<float>& job, std::size_t begin, std::size_t end) {
  block_smooth_of(job, begin, end);
}
KINEMA_CLONED void block_smooth(const BlockSmoothJob<double>& job, std::size_t begin, std::size_t end) {
  block_smooth_of(job, begin, end);
}
KINEMA_CLONED void prolong_add(const ProlongJob<float>& job, std::size_t begin, std::size_t end) { prolong_of(job, begin, end); }
KINEMA_CLONED void prolong_add(const ProlongJob<double>& job, std::size_t begin, std::size_t end) { prolong_of(job, begin, end); }
KINEMA_CLONED void subtract_from(const float* const r[3], float* const out[3], std::size_t begin, std::size_t end) {
  subtract_of(r, out, begin, end);
}
KINEMA_CLONED void subtract_from(const double* const r[3], double* const out[3], std::size_t begin, std::size_t end) {
  subtract_of(r, out, begin, end);
}
KINEMA_CLONED double dot3(const float* const a[3], const float* const b[3], std::size_t begin, std::size_t end) {
  return dot_of(a, b, begin, end);
}
KINEMA_CLONED double dot3(const double* const a[3], const double* const b[3], std::size_t begin, std::size_t end) {
  return dot_of(a, b, begin, end);
}

KINEMA_CLONED double spring_product(const SpringProductJob<float>& job, std::size_t begin, std::size_t end) {
  return product_of(job, begin, end);
}
KINEMA_CLONED double spring_product(const SpringProductJob<double>& job, std::size_t begin, std::size_t end) {
  return product_of(job, begin, end);
}
KINEMA_CLONED void cg_update(const CgUpdateJob<float>& job, std::size_t begin, std::size_t end, double sums[2]) {
  update_of(job, begin, end, sums);
}
KINEMA_CLONED void cg_update(const CgUpdateJob<double>& job, std::size_t begin, std::size_t end, double sums[2]) {
  update_of(job, begin, end, sums);
}
KINEMA_CLONED void cg_direction(const CgDirectionJob<float>& job, std::size_t begin, std::size_t end) {
  direction_of(job, begin, end);
}
KINEMA_CLONED void cg_direction(const CgDirectionJob<double>& job, std::size_t begin, std::size_t end) {
  direction_of(job, begin, end);
}

}  // namespace kinema::kernels
