// The implicit path's passes of implicit_kernels.hpp, cloned per instruction set with the
// same operations in each (the library builds with -ffp-contract=off: no fused multiply-add
// is formed, so every clone rounds as the baseline one does).
#include "kernels/implicit_kernels.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "kernels/cloned.hpp"
#include "kernels/kernels.hpp"

namespace kinema::kernels {
namespace {

constexpr std::size_t kLanes = kSpringSlice;

// The other ends of one entry's lanes: consecutive bodies (read where they are), or gathered
// into `gathered` by the slots' neighbours. A masked run (some lanes' slots empty) is
// gathered too: an empty slot's neighbour is its body. (Whole slices: load_other_ends.)
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

// One entry of a partial slice (its first `lanes` lanes).
template <class T>
[[gnu::always_inline]] inline void add_entry(const SpringProductJob<T>& job, std::size_t entry, std::size_t lanes,
                                             const T (&own)[3][kLanes], const T* const (&other)[3],
                                             T (&sum)[3][kLanes]) {
  const std::size_t n = lanes;
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

// The partial slice that ends a set padded to less than a slice (whole slices:
// product_slice_full): its own values and sums in local arrays; p . out to a running sum per
// lane (Residual: out = minuend - the product, no sum).
template <bool Residual, class T>
[[gnu::always_inline]] inline void product_slice(const SpringProductJob<T>& job, std::size_t first, std::size_t lanes,
                                                 double (&dots)[kLanes]) {
  const std::size_t n = lanes;
  alignas(64) T own[3][kLanes], sum[3][kLanes], gathered[3][kLanes];
  for (int d = 0; d < 3; ++d) {
    for (std::size_t l = 0; l < n; ++l) own[d][l] = job.p[d][first + l], sum[d][l] = job.cm * job.mass[first + l] * own[d][l];
  }
  if (first < job.covered) {
    const std::size_t slice = first / kLanes;
    for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
      const T* other[3];
      other_ends<false>(job, e, lanes, gathered, other);
      add_entry(job, e, lanes, own, other, sum);
    }
  }
  // Fixed bodies' out is 0: selected on the bits (a mass is never negative, so it is 0 when
  // its bits past the sign are), which vectorizes where a float compare and branch did not.
  using Bits = std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>;
  const T* __restrict mass = job.mass + first;
  for (int d = 0; d < 3; ++d) {
    T* __restrict out = job.out[d] + first;
    const T *__restrict own_d = own[d], *__restrict sum_d = sum[d];
    const T* __restrict minuend = Residual ? job.minuend[d] + first : nullptr;
    for (std::size_t l = 0; l < n; ++l) {
      const Bits keep = std::bit_cast<Bits>(mass[l]) << 1 == 0 ? Bits(0) : ~Bits(0);
      const T value = std::bit_cast<T>(std::bit_cast<Bits>(sum_d[l]) & keep);
      if constexpr (Residual) {
        out[l] = minuend[l] - value;
      } else {
        out[l] = value;
        dots[l] += double(own_d[l]) * double(value);
      }
    }
  }
}

// A whole slice as vectors of its kLanes lanes (GCC's vector extension: every clone splits
// them into its own registers). The same operations per lane as product_slice, but the sums
// stay in registers across the slice's entries, where the arrays of product_slice went to
// memory and back at every entry.
template <class T>
struct SliceVectors {
  typedef T V __attribute__((vector_size(kLanes * sizeof(T))));
  using Bits = std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>;
  typedef Bits B __attribute__((vector_size(kLanes * sizeof(T))));
  typedef double D __attribute__((vector_size(kLanes * sizeof(double))));
};

// v from the values at p (an out-parameter: a vector returned by value warns of its ABI in
// the clones without wide registers, although every call is inlined).
template <class V, class T>
[[gnu::always_inline]] inline void load_lanes(V& v, const T* p) {
  std::memcpy(&v, p, sizeof v);
}

// A whole entry's other ends as vectors. A masked run (contiguous -(base + 2): lane l's other
// end is base + l where the lane has a spring, the lane's own body where it has none) loads
// base's run and takes the own value in the empty lanes, the values a gather would give.
template <class T, class V>
[[gnu::always_inline]] inline void load_other_ends(const SpringProductJob<T>& job, std::size_t entry,
                                                   std::size_t first, const V (&own)[3], V (&other)[3]) {
  using B = typename SliceVectors<T>::B;
  const std::int32_t code = job.contiguous[entry];
  if (code >= 0) {
    for (int d = 0; d < 3; ++d) load_lanes(other[d], job.p[d] + code);
    return;
  }
  if (code == -1) {
    alignas(64) T gathered[3][kLanes];
    const T* from[3];
    other_ends<true>(job, entry, kLanes, gathered, from);
    for (int d = 0; d < 3; ++d) load_lanes(other[d], from[d]);
    return;
  }
  typedef std::int32_t I __attribute__((vector_size(kLanes * sizeof(std::int32_t))));
  typedef std::make_signed_t<typename SliceVectors<T>::Bits> S;
  typedef S Wide __attribute__((vector_size(kLanes * sizeof(T))));
  I neighbor, self;
  load_lanes(neighbor, job.neighbor + entry * kLanes);
  for (std::size_t l = 0; l < kLanes; ++l) self[l] = std::int32_t(first + l);
  const B empty = (B)__builtin_convertvector(neighbor == self, Wide);
  const std::size_t base = std::size_t(-code - 2);
  for (int d = 0; d < 3; ++d) {
    V run;
    load_lanes(run, job.p[d] + base);
    other[d] = (V)(((B)run & ~empty) | ((B)own[d] & empty));
  }
}

template <bool Residual, class T>
[[gnu::always_inline]] inline void product_slice_full(const SpringProductJob<T>& job, std::size_t first,
                                                      double (&dots)[kLanes]) {
  using V = typename SliceVectors<T>::V;
  using B = typename SliceVectors<T>::B;
  using D = typename SliceVectors<T>::D;
  V own[3], sum[3], mass;
  load_lanes(mass, job.mass + first);
  const V cm_mass = job.cm * mass;
  for (int d = 0; d < 3; ++d) load_lanes(own[d], job.p[d] + first), sum[d] = cm_mass * own[d];
  if (first < job.covered) {
    const std::size_t slice = first / kLanes;
    const std::size_t entries = job.slice_offset[(job.covered + kLanes - 1) / kLanes];
    for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
      V other[3];
      load_other_ends(job, e, first, own, other);
      const std::size_t at = e * kLanes;
      constexpr std::size_t ahead_entries = 32, ahead = ahead_entries * kLanes;
      for (const T* a : {job.unit[0] + at, job.unit[1] + at, job.unit[2] + at, job.along + at, job.across + at}) {
        __builtin_prefetch(a + ahead);
      }
      // A gathered entry's neighbour indices are read for it alone (a few entries in a
      // hundred): a miss each, unless fetched as early as the slots' arrays.
      if (e + ahead_entries < entries && job.contiguous[e + ahead_entries] < 0) {
        __builtin_prefetch(job.neighbor + ahead + at);
      }
      V ux, uy, uz, along, across;
      load_lanes(ux, job.unit[0] + at), load_lanes(uy, job.unit[1] + at), load_lanes(uz, job.unit[2] + at);
      load_lanes(along, job.along + at), load_lanes(across, job.across + at);
      const V dx = other[0] - own[0], dy = other[1] - own[1], dz = other[2] - own[2];
      const V s = along * (ux * dx + uy * dy + uz * dz);
      sum[0] += s * ux + across * dx;
      sum[1] += s * uy + across * dy;
      sum[2] += s * uz + across * dz;
    }
  }
  B mass_bits;
  load_lanes(mass_bits, job.mass + first);
  const B keep = (mass_bits << 1) != 0;
  for (int d = 0; d < 3; ++d) {
    const V value = (V)((B)sum[d] & keep);
    if constexpr (Residual) {
      V minuend;
      load_lanes(minuend, job.minuend[d] + first);
      const V out = minuend - value;
      std::memcpy(job.out[d] + first, &out, sizeof out);
    } else {
      std::memcpy(job.out[d] + first, &value, sizeof value);
      D dot;
      load_lanes(dot, dots);
      dot += __builtin_convertvector(own[d], D) * __builtin_convertvector(value, D);
      std::memcpy(dots, &dot, sizeof dot);
    }
  }
}

// Slice by slice (a set padded to less than a slice ends in a partial one); the lanes' sums
// added in lane order at the end.
template <bool Residual, class T>
[[gnu::always_inline]] inline double product_of(const SpringProductJob<T>& job, std::size_t begin, std::size_t end) {
  double dots[kLanes] = {};
  std::size_t first = begin;
  for (; first + kLanes <= end; first += kLanes) product_slice_full<Residual>(job, first, dots);
  if (first < end) product_slice<Residual>(job, first, end - first, dots);
  double total = 0;
  for (double x : dots) total += x;
  return total;
}

// One slice's lanes of one array, through restrict parameters: stores through the job's
// pointers could otherwise alias alpha and each other, and the loop would not vectorize.
// WithZ false: z and r . z are left to another preconditioner.
template <bool WithZ, class T>
[[gnu::always_inline]] inline void update_lanes(T* __restrict x, T* __restrict r, T* __restrict z,
                                                const T* __restrict p, const T* __restrict q,
                                                const T* __restrict inv_diag, T alpha, std::size_t lanes,
                                                double (&rz)[kLanes], double (&rr)[kLanes]) {
  for (std::size_t l = 0; l < lanes; ++l) {
    x[l] += alpha * p[l];
    const T rl = r[l] - alpha * q[l];
    r[l] = rl;
    if constexpr (WithZ) {
      const T zl = inv_diag[l] * rl;
      z[l] = zl;
      rz[l] += double(rl) * double(zl);
    }
    rr[l] += double(rl) * double(rl);
  }
}

// A whole slice as update_lanes does it, with the running sums in registers (vectors of
// the slice's lanes) where update_lanes' arrays went to memory and back for every array.
template <bool WithZ, class T, class D>
[[gnu::always_inline]] inline void update_slice_full(const CgUpdateJob<T>& job, std::size_t first, D& rz, D& rr) {
  using V = typename SliceVectors<T>::V;
  for (int d = 0; d < 3; ++d) {
    V x, r, p, q;
    load_lanes(x, job.x[d] + first), load_lanes(r, job.r[d] + first);
    load_lanes(p, job.p[d] + first), load_lanes(q, job.q[d] + first);
    x += job.alpha * p;
    r = r - job.alpha * q;
    std::memcpy(job.x[d] + first, &x, sizeof x);
    std::memcpy(job.r[d] + first, &r, sizeof r);
    const D r_wide = __builtin_convertvector(r, D);
    if constexpr (WithZ) {
      V inv_diag;
      load_lanes(inv_diag, job.inv_diag[d] + first);
      const V z = inv_diag * r;
      std::memcpy(job.z[d] + first, &z, sizeof z);
      rz += r_wide * __builtin_convertvector(z, D);
    }
    rr += r_wide * r_wide;
  }
}

template <bool WithZ, class T>
[[gnu::always_inline]] inline void update_of(const CgUpdateJob<T>& job, std::size_t begin, std::size_t end,
                                             double sums[2]) {
  using D = typename SliceVectors<T>::D;
  D rz_lanes = {}, rr_lanes = {};
  // A copy no store can reach: the job's pointers stay in registers across the stores.
  const CgUpdateJob<T> local = job;
  std::size_t first = begin;
  for (; first + kLanes <= end; first += kLanes) update_slice_full<WithZ>(local, first, rz_lanes, rr_lanes);
  double rz[kLanes], rr[kLanes];
  std::memcpy(rz, &rz_lanes, sizeof rz), std::memcpy(rr, &rr_lanes, sizeof rr);
  if (first < end) {  // a set padded to less than a slice past its last whole one
    for (int d = 0; d < 3; ++d) {
      update_lanes<WithZ>(job.x[d] + first, job.r[d] + first, WithZ ? job.z[d] + first : nullptr,
                                 job.p[d] + first, job.q[d] + first, job.inv_diag[d] + first, job.alpha, end - first,
                                 rz, rr);
    }
  }
  for (std::size_t l = 0; l < kLanes; ++l) sums[0] += rz[l], sums[1] += rr[l];
}

template <class T>
[[gnu::always_inline]] inline void direction_lanes(T* __restrict p, const T* __restrict z, T beta, std::size_t begin,
                                                   std::size_t end) {
  for (std::size_t i = begin; i < end; ++i) p[i] = z[i] + beta * p[i];
}

template <class T>
[[gnu::always_inline]] inline void direction_of(const CgDirectionJob<T>& job, std::size_t begin, std::size_t end) {
  for (int d = 0; d < 3; ++d) direction_lanes(job.p[d], job.z[d], job.beta, begin, end);
}

// One entry's lanes, each pointer a parameter of its own: GCC keeps restrict parameters apart
// where restrict locals of an inlined function were not, and the loop vectorizes. The lengths'
// zero tests select after dividing by a safe length (a division under a branch does not run
// for all lanes at once); each lane's operations are those of the plain formula.
template <class T>
[[gnu::always_inline]] inline void jacobian_lanes(const T* __restrict ox, const T* __restrict oy, const T* __restrict oz,
                                                  const T* __restrict x, const T* __restrict y, const T* __restrict z,
                                                  const T* __restrict rest, const T* __restrict kk,
                                                  const T* __restrict damping, T sc, T sk, T* __restrict ux,
                                                  T* __restrict uy, T* __restrict uz, T* __restrict k_along,
                                                  T* __restrict k_across, T* __restrict a_along, T* __restrict a_across,
                                                  T* __restrict dx_, T* __restrict dy_, T* __restrict dz_, std::size_t n) {
  for (std::size_t l = 0; l < n; ++l) {
    const T dx = ox[l] - x[l], dy = oy[l] - y[l], dz = oz[l] - z[l];
    const T length2 = ((T(0) + dx * dx) + dy * dy) + dz * dz;
    // A k of -0 counts as +0: no zero's sign in the products hangs on how k was written.
    const T length = std::sqrt(length2), k = kk[l] + T(0);
    const bool apart = length > 0;
    const T safe = apart ? length : T(1);
    // Stretched: the geometric stiffness k (1 - rest / length) across the spring. Under
    // compression it would be negative: left out, so the matrix stays definite.
    const T r = rest[l] < T(0) ? T(0) : rest[l], g = T(1) - r / length;
    const T across = apart ? (g > T(0) ? g : T(0)) : T(0);
    const T along_k = k * (T(1) - across), across_k = k * across;
    k_along[l] = along_k, k_across[l] = across_k;
    const T w = sc * damping[l] + sk * along_k, wa = sk * across_k;
    a_along[l] = w, a_across[l] = wa;
    const T q0 = dx / safe, q1 = dy / safe, q2 = dz / safe;
    const T u0 = apart ? q0 : T(0), u1 = apart ? q1 : T(0), u2 = apart ? q2 : T(0);
    ux[l] = u0, uy[l] = u1, uz[l] = u2;
    dx_[l] -= w * u0 * u0 + wa, dy_[l] -= w * u1 * u1 + wa, dz_[l] -= w * u2 * u2 + wa;
  }
}

// One entry's slots: the other ends gathered, then the lanes.
template <bool Full, class T>
[[gnu::always_inline]] inline void jacobian_entry(const JacobianJob<T>& job, std::size_t first, std::size_t entry,
                                                  std::size_t lanes) {
  const std::size_t n = Full ? kLanes : lanes;
  const std::size_t at = entry * kLanes;
  alignas(64) T other[3][kLanes];
  for (int d = 0; d < 3; ++d) {
    const std::int32_t* __restrict neighbor = job.neighbor + at;
    const T* __restrict x = job.x[d];
    T* __restrict o = other[d];
    for (std::size_t l = 0; l < n; ++l) o[l] = x[std::size_t(neighbor[l])];
  }
  jacobian_lanes(other[0], other[1], other[2], job.x[0] + first, job.x[1] + first, job.x[2] + first, job.rest + at,
                 job.k + at, job.damping + at, job.sc, job.sk, job.unit[0] + at, job.unit[1] + at, job.unit[2] + at,
                 job.k_along + at, job.k_across + at, job.a_along + at, job.a_across + at, job.diag[0] + first,
                 job.diag[1] + first, job.diag[2] + first, n);
}

template <class T>
[[gnu::always_inline]] inline void jacobian_of(const JacobianJob<T>& job, std::size_t begin, std::size_t end) {
  const std::size_t stop = std::min(end, job.covered);
  for (std::size_t slice = begin / kLanes; slice * kLanes < stop; ++slice) {
    // A set padded to fewer than kLanes bodies past its last slice's first.
    const std::size_t lanes = std::min(kLanes, end - slice * kLanes);
    for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
      if (lanes == kLanes) {
        jacobian_entry<true>(job, slice * kLanes, e, kLanes);
      } else {
        jacobian_entry<false>(job, slice * kLanes, e, lanes);
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

// out = base + B in over [begin, end): every pointer a parameter of its own, so that GCC keeps
// them apart and vectorizes (restrict locals of an inlined function did not vectorize).
template <bool WithBase, class T>
[[gnu::always_inline]] inline void smooth_lanes(const T* __restrict xx, const T* __restrict yy, const T* __restrict zz,
                                                const T* __restrict xy, const T* __restrict xz, const T* __restrict yz,
                                                const T* __restrict x, const T* __restrict y, const T* __restrict z,
                                                const T* __restrict bx, const T* __restrict by, const T* __restrict bz,
                                                T* __restrict ox, T* __restrict oy, T* __restrict oz, std::size_t begin,
                                                std::size_t end) {
  for (std::size_t i = begin; i < end; ++i) {
    const T sx = xx[i] * x[i] + xy[i] * y[i] + xz[i] * z[i];
    const T sy = xy[i] * x[i] + yy[i] * y[i] + yz[i] * z[i];
    const T sz = xz[i] * x[i] + yz[i] * y[i] + zz[i] * z[i];
    if constexpr (WithBase) {
      ox[i] = bx[i] + sx, oy[i] = by[i] + sy, oz[i] = bz[i] + sz;
    } else {
      ox[i] = sx, oy[i] = sy, oz[i] = sz;
    }
  }
}

template <class T>
[[gnu::always_inline]] inline void block_smooth_of(const BlockSmoothJob<T>& job, std::size_t begin, std::size_t end) {
  const T* const* m = job.block;
  if (job.base[0] == nullptr) {
    smooth_lanes<false>(m[0], m[1], m[2], m[3], m[4], m[5], job.in[0], job.in[1], job.in[2], job.in[0], job.in[1],
                        job.in[2], job.out[0], job.out[1], job.out[2], begin, end);
  } else {
    smooth_lanes<true>(m[0], m[1], m[2], m[3], m[4], m[5], job.in[0], job.in[1], job.in[2], job.base[0], job.base[1],
                       job.base[2], job.out[0], job.out[1], job.out[2], begin, end);
  }
}

template <class T>
[[gnu::always_inline]] inline void prolong_lanes(const std::int32_t* __restrict node, const T* __restrict values,
                                                 T* __restrict out, std::size_t begin, std::size_t end) {
  for (std::size_t i = begin; i < end; ++i) out[i] += values[node[i]];
}

template <class T>
[[gnu::always_inline]] inline void prolong_of(const ProlongJob<T>& job, std::size_t begin, std::size_t end) {
  for (int d = 0; d < 3; ++d) prolong_lanes(job.node, job.values[d], job.out[d], begin, end);
}

constexpr std::size_t kGroup = kCoarseGroup;

// One row of a group's edges: y += C (x_k - x_j) where the lane has an edge (a lane without
// one names its own node, which no edge joins).
[[gnu::always_inline]] inline void coarse_row(const std::uint32_t* __restrict column, const double* __restrict a0,
                                              const double* __restrict a1, const double* __restrict a2,
                                              const double* __restrict a3, const double* __restrict a4,
                                              const double* __restrict a5, const double* __restrict x,
                                              const double (&own)[3][kGroup], double (&y)[3][kGroup],
                                              std::size_t first) {
  for (std::size_t l = 0; l < kGroup; ++l) {
    const std::size_t j = std::size_t(column[l]);
    const bool edge = j != first + l;
    const double d0 = own[0][l] - x[3 * j], d1 = own[1][l] - x[3 * j + 1], d2 = own[2][l] - x[3 * j + 2];
    const double c0 = a0[l] * d0 + a3[l] * d1 + a4[l] * d2;
    const double c1 = a3[l] * d0 + a1[l] * d1 + a5[l] * d2;
    const double c2 = a4[l] * d0 + a5[l] * d1 + a2[l] * d2;
    // Selected on the bits: a float select here kept a branch and the loop scalar.
    const std::uint64_t keep = edge ? ~std::uint64_t(0) : 0;
    const double y0 = y[0][l], y1 = y[1][l], y2 = y[2][l];
    y[0][l] = std::bit_cast<double>((std::bit_cast<std::uint64_t>(y0 + c0) & keep) | (std::bit_cast<std::uint64_t>(y0) & ~keep));
    y[1][l] = std::bit_cast<double>((std::bit_cast<std::uint64_t>(y1 + c1) & keep) | (std::bit_cast<std::uint64_t>(y1) & ~keep));
    y[2][l] = std::bit_cast<double>((std::bit_cast<std::uint64_t>(y2 + c2) & keep) | (std::bit_cast<std::uint64_t>(y2) & ~keep));
  }
}

[[gnu::always_inline]] inline void coarse_group(const CoarseResidualJob& job, std::size_t g) {
  const std::size_t first = g * kGroup;
  const double* __restrict x = job.x;
  const double* __restrict m = job.diagonal + 6 * first;
  alignas(64) double own[3][kGroup], y[3][kGroup];
  for (std::size_t l = 0; l < kGroup; ++l) {
    const double x0 = x[3 * (first + l)], x1 = x[3 * (first + l) + 1], x2 = x[3 * (first + l) + 2];
    own[0][l] = x0, own[1][l] = x1, own[2][l] = x2;
    const double* a = m + 6 * l;
    y[0][l] = a[0] * x0 + a[3] * x1 + a[4] * x2;
    y[1][l] = a[3] * x0 + a[1] * x1 + a[5] * x2;
    y[2][l] = a[4] * x0 + a[5] * x1 + a[2] * x2;
  }
  for (std::uint32_t r = job.group_row[g]; r < job.group_row[g + 1]; ++r) {
    const std::size_t at = std::size_t(r) * kGroup;
    coarse_row(job.column + at, job.edge[0] + at, job.edge[1] + at, job.edge[2] + at, job.edge[3] + at,
               job.edge[4] + at, job.edge[5] + at, x, own, y, first);
  }
  const double* __restrict b = job.b + 3 * first;
  double* __restrict out = job.out + 3 * first;
  for (std::size_t l = 0; l < kGroup; ++l) {
    for (int d = 0; d < 3; ++d) out[3 * l + d] = b[3 * l + d] - y[d][l];
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
KINEMA_CLONED double dot3(const float* const a[3], const float* const b[3], std::size_t begin, std::size_t end) {
  return dot_of(a, b, begin, end);
}
KINEMA_CLONED double dot3(const double* const a[3], const double* const b[3], std::size_t begin, std::size_t end) {
  return dot_of(a, b, begin, end);
}

KINEMA_CLONED void coarse_residual(const CoarseResidualJob& job, std::size_t begin, std::size_t end) {
  for (std::size_t g = begin / kGroup; g * kGroup < end; ++g) coarse_group(job, g);
}

KINEMA_CLONED double spring_product(const SpringProductJob<float>& job, std::size_t begin, std::size_t end) {
  return job.minuend[0] ? product_of<true>(job, begin, end) : product_of<false>(job, begin, end);
}
KINEMA_CLONED double spring_product(const SpringProductJob<double>& job, std::size_t begin, std::size_t end) {
  return job.minuend[0] ? product_of<true>(job, begin, end) : product_of<false>(job, begin, end);
}
KINEMA_CLONED void cg_update(const CgUpdateJob<float>& job, std::size_t begin, std::size_t end, double sums[2]) {
  job.z[0] ? update_of<true>(job, begin, end, sums) : update_of<false>(job, begin, end, sums);
}
KINEMA_CLONED void cg_update(const CgUpdateJob<double>& job, std::size_t begin, std::size_t end, double sums[2]) {
  job.z[0] ? update_of<true>(job, begin, end, sums) : update_of<false>(job, begin, end, sums);
}
KINEMA_CLONED void cg_direction(const CgDirectionJob<float>& job, std::size_t begin, std::size_t end) {
  direction_of(job, begin, end);
}
KINEMA_CLONED void cg_direction(const CgDirectionJob<double>& job, std::size_t begin, std::size_t end) {
  direction_of(job, begin, end);
}

}  // namespace kinema::kernels
