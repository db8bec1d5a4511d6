#pragma once
// The coupled terms' kernels: N-body gravity (SIMD over targets, sources staged in tiles)
// and spring networks (SIMD over the bodies of a slice, neighbours loaded or gathered).
// Every lane runs the same operations in the same order on every instruction set, so the
// bits agree across them.

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <limits>

#include "kernels/kernel_impl.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

// Sources staged per pass: a tile of positions and masses stays in L1 while every target
// group of the block runs over it.
inline constexpr std::size_t kSourceTile = 512;

// The sources [first, first + kSourceTile) that have mass, in index order: kinematic and
// padding bodies (inv_mass 0) neither attract nor cost an interaction.
template <class T>
struct SourceTile {
  alignas(64) T x[3][kSourceTile];
  alignas(64) T mass[kSourceTile];
  alignas(64) T mass_three_halves[kSourceTile];  // fast_inverse_cube's factor with the mass
  std::size_t count = 0;
  T largest_mass = 0;

  void fill(const NBodyJob<T>& job, std::size_t first) {
    count = 0;
    largest_mass = 0;
    for (std::size_t j = first; j < std::min(job.sources, first + kSourceTile); ++j) {
      const T w = job.inv_mass[j];
      if (w == 0) continue;
      for (int d = 0; d < 3; ++d) x[d][count] = job.x[d][j];
      mass[count] = T(1) / w;
      mass_three_halves[count] = T(1.5) / w;
      largest_mass = std::max(largest_mass, mass[count++]);
    }
  }

  // Whether every pair's factor and its parts are finite: s <= 2.5 (1 + 1.5 2^-12)^3 m eps^-3
  // < 2.6 m eps^-3 (fast, with 3/2 m; the exact factor is less), and eps^3 is no denormal.
  // Then a body's pair with itself (or a twin at its point) adds exactly +-0 to its sums, as
  // with the mask. Unlike the mask, a pair closer than about 1e-23 (its squared distance
  // underflows to 0; 1e-19 where the host flushes denormals) pulls by the softened formula
  // instead of counting as one point.
  bool pairs_vanish_at_zero(T eps2) const {
    const double bound = double(std::numeric_limits<T>::max()) / 8;
    const double largest_factor = 2.6 * double(largest_mass) * std::max(1.0, std::pow(double(eps2), -1.5));
    return double(eps2) >= 1e-20 && largest_factor < bound;
  }
};

// m r2^(-3/2) from an approximate y = 1 / sqrt(r2) (rough_inverse_root), corrected once:
// r2^(-3/2) = y^3 (r2 y^2)^(-3/2) = y^3 (1 - e)^(-3/2) ~ y^3 (1 + 3/2 e) with e = 1 - r2 y^2,
// which is 3/2 y^3 (5/3 - r2 y^2); the 3/2 comes with the mass (SourceTile).
// The series' first dropped term is 15/8 e^2, e ~ 2 (y's relative error): below 3e-8 for
// AVX-512's 14-bit start, 1.1e-6 for SSE2's and AVX2's 12 bits, before float round-off.
// A pair too far apart for its squared distance (inf: the estimate's root is 0, and inf 0 is
// NaN) is taken at the largest value instead and pulls by about 0, as the exact m / inf does;
// lane_min keeps a NaN (its second operand) and every finite r2 as it is.
template <class V>
KINEMA_INLINE V fast_inverse_cube(V r2, V mass_three_halves) {
  r2 = lane_min(V(std::numeric_limits<value_t<V>>::max()), r2);
  const V y = rough_inverse_root(r2), y2 = y * y;
  return (mass_three_halves * y) * y2 * mul_add(V(0) - r2, y2, V(value_t<V>(5) / 3));
}

// m r2^(-3/2), exact (the only kind for double) or fast.
template <bool Exact, class V>
KINEMA_INLINE V pair_factor(V r2, value_t<V> mass, value_t<V> mass_three_halves) {
  if constexpr (!Exact && std::is_same_v<value_t<V>, float>) return fast_inverse_cube(r2, V(mass_three_halves));
  return V(mass) / (r2 * root(r2));
}

// The partial sums of U lane groups of targets, starting at target i, over one tile. The
// groups in Exact (bit u) take the exact root and division, which run on the divider; the
// others fast_inverse_cube, which runs on the FMA pipes. Mixed, both units work at once.
// Masked: a pair at distance 0 gets s = 0 (needed unless pairs_vanish_at_zero).
template <bool Masked, unsigned Exact, int U, class V>
KINEMA_INLINE void gravity_from_tile(const SourceTile<value_t<V>>& tile, V eps2,
                                     const NBodyJob<value_t<V>>& job, std::size_t i,
                                     value_t<V>* sum[3], std::size_t at) {
  constexpr std::size_t W = Lane<V>::width;
  V x[U][3], a[U][3];
  for (int u = 0; u < U; ++u) {
    for (int d = 0; d < 3; ++d) {
      x[u][d] = load<V>(job.x[d] + i + u * W);
      a[u][d] = load<V>(sum[d] + at + u * W);
    }
  }
  for (std::size_t j = 0; j < tile.count; ++j) {
    const V sx(tile.x[0][j]), sy(tile.x[1][j]), sz(tile.x[2][j]);
    static_for<U>([&](auto u) {
      const V dx = sx - x[u][0], dy = sy - x[u][1], dz = sz - x[u][2];
      const V d2 = mul_add(dx, dx, mul_add(dy, dy, dz * dz)), r2 = d2 + eps2;
      V s = pair_factor<((Exact >> u) & 1) != 0>(r2, tile.mass[j], tile.mass_three_halves[j]);
      // A body and itself (or a twin at the same point): no force, whatever m / eps^3 is.
      if constexpr (Masked) s = pick(d2 != V(0), s, V(0));
      a[u][0] = mul_add(s, dx, a[u][0]);
      a[u][1] = mul_add(s, dy, a[u][1]);
      a[u][2] = mul_add(s, dz, a[u][2]);
    });
  }
  for (int u = 0; u < U; ++u) {
    for (int d = 0; d < 3; ++d) store(sum[d] + at + u * W, a[u][d]);
  }
}

// One tile's pairs for the targets [begin, end). Exact: every group exact. Fast: lane
// groups alternate, the even ones (counting from target 0, so a group's kind never depends
// on where a job's range starts) exact, the odd ones fast.
template <bool Fast, bool Masked, class V>
void targets_over_tile(const SourceTile<value_t<V>>& tile, V eps2, const NBodyJob<value_t<V>>& job,
                       std::size_t begin, std::size_t end, value_t<V>* sum[3]) {
  constexpr std::size_t W = Lane<V>::width;
  constexpr int U = 4;  // target groups in registers: enough to hide the divider's latency
  constexpr unsigned kAll = 0xF, kEven = Fast ? 0x5 : kAll, kOdd = Fast ? 0xA : kAll;
  const bool starts_even = (begin / W) % 2 == 0;
  std::size_t i = begin;
  for (; i + U * W <= end; i += U * W) {
    if (starts_even) gravity_from_tile<Masked, kEven, U, V>(tile, eps2, job, i, sum, i - begin);
    else gravity_from_tile<Masked, kOdd, U, V>(tile, eps2, job, i, sum, i - begin);
  }
  for (; i < end; i += W) {
    if ((i / W) % 2 == 0) gravity_from_tile<Masked, kEven & 1, 1, V>(tile, eps2, job, i, sum, i - begin);
    else gravity_from_tile<Masked, kOdd & 1, 1, V>(tile, eps2, job, i, sum, i - begin);
  }
}

template <bool Fast, class V>
void nbody_sums(const NBodyJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  using T = value_t<V>;
  constexpr std::size_t W = Lane<V>::width;
  assert(end - begin <= kMaxNBodyTargets);
  alignas(64) T sum_x[kMaxNBodyTargets]{}, sum_y[kMaxNBodyTargets]{}, sum_z[kMaxNBodyTargets]{};
  T* sum[3] = {sum_x, sum_y, sum_z};
  SourceTile<T> tile;
  const V eps2(job.eps2);
  for (std::size_t first = 0; first < job.sources; first += kSourceTile) {
    tile.fill(job, first);
    // The mask costs an FMA-pipe operation per group, which the fast variant is bound by.
    if constexpr (Fast) {
      if (tile.pairs_vanish_at_zero(job.eps2)) {
        targets_over_tile<Fast, false, V>(tile, eps2, job, begin, end, sum);
        continue;
      }
    }
    targets_over_tile<Fast, true, V>(tile, eps2, job, begin, end, sum);
  }
  const V scale(job.scale_G);
  for (std::size_t i = begin; i < end; i += W) {
    const V inv_mass = load<V>(job.inv_mass + i);
    for (int d = 0; d < 3; ++d) {
      const V a = load<V>(job.acc[d] + i);
      store(job.acc[d] + i, pick(inv_mass != V(0), mul_add(scale, load<V>(sum[d] + i - begin), a), a));
    }
  }
}

// The fast variant exists for float; double jobs always take the exact sums.
template <class V>
void nbody(const NBodyJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  if constexpr (std::is_same_v<value_t<V>, float>) {
    if (job.fast) return nbody_sums<true, V>(job, begin, end);
  }
  nbody_sums<false, V>(job, begin, end);
}

// One spring slot's force on the lanes' bodies: x, v theirs, xj, vj the other ends'.
// Masked: lanes whose rest length is negative hold no spring and keep f as it is, whatever
// state the body loaded for them has.
template <bool Masked, class V>
KINEMA_INLINE void add_spring(const Vec<V>& x, const Vec<V>& v, const Vec<V>& xj, const Vec<V>& vj,
                              V rest, V k, V damping, Vec<V>& f) {
  Vec<V> d, dv;
  for (int c = 0; c < 3; ++c) d.c[c] = xj.c[c] - x.c[c], dv.c[c] = vj.c[c] - v.c[c];
  const V length = root(mul_add(d.c[0], d.c[0], mul_add(d.c[1], d.c[1], d.c[2] * d.c[2])));
  const V inv = pick(length != V(0), V(1) / length, V(0));
  Vec<V> u;
  for (int c = 0; c < 3; ++c) u.c[c] = d.c[c] * inv;
  const V along = mul_add(dv.c[0], u.c[0], mul_add(dv.c[1], u.c[1], dv.c[2] * u.c[2]));
  // Both ends compute the same coefficient and opposite unit vectors: F_j = -F_i exactly.
  const V coefficient = mul_add(k, length - rest, damping * along);
  for (int c = 0; c < 3; ++c) {
    if constexpr (Masked) {
      f.c[c] = pick(rest >= V(0), mul_add(coefficient, u.c[c], f.c[c]), f.c[c]);
    } else {
      f.c[c] = mul_add(coefficient, u.c[c], f.c[c]);
    }
  }
}

// The other ends of an entry's springs: consecutive bodies from `first` (first >= 0), or
// gathered through the entry's neighbour indices.
template <class V>
KINEMA_INLINE Vec<V> other_ends(const value_t<V>* const p[3], const SpringJob<value_t<V>>& job,
                                std::size_t entry, std::size_t lane, std::int32_t first) {
  Vec<V> out;
  for (int c = 0; c < 3; ++c) {
    out.c[c] = first >= 0 ? load_unaligned<V>(p[c] + first + lane)
                          : gather<V>(p[c], job.neighbor + entry * kSpringSlice + lane);
  }
  return out;
}

template <bool Masked, class V>
KINEMA_INLINE void add_entry(const SpringJob<value_t<V>>& job, std::size_t e, std::size_t lane,
                             std::int32_t first, const Vec<V>& x, const Vec<V>& v, Vec<V>& f) {
  const std::size_t at = e * kSpringSlice + lane;
  add_spring<Masked>(x, v, other_ends<V>(job.x, job, e, lane, first), other_ends<V>(job.v, job, e, lane, first),
                     load<V>(job.rest + at), load<V>(job.k + at), load<V>(job.damping + at), f);
}

inline constexpr std::size_t kPrefetchSlots = 32 * kSpringSlice;

template <class V>
void springs(const SpringJob<value_t<V>>& job, std::size_t begin, std::size_t end) {
  constexpr std::size_t W = Lane<V>::width;
  assert(begin % kSpringSlice == 0);  // a slice never straddles two blocks
  const std::size_t stop = std::min(end, job.covered);
  for (std::size_t slice = begin / kSpringSlice; slice * kSpringSlice < stop; ++slice) {
    for (std::size_t lane = 0; lane < kSpringSlice; lane += W) {
      const std::size_t i = slice * kSpringSlice + lane;
      if (i >= end) break;
      const Vec<V> x = load3<V>(job.x, i), v = load3<V>(job.v, i);
      Vec<V> f{};
      for (int c = 0; c < 3; ++c) f.c[c] = V(0);
      for (std::size_t e = job.slice_offset[slice]; e < job.slice_offset[slice + 1]; ++e) {
        const std::size_t at = e * kSpringSlice + lane;
        // Nine streams at once (state, parameters, forces) outrun the hardware prefetcher:
        // fetch the parameters kPrefetchSlots ahead.
        for (const value_t<V>* p : {job.rest, job.k, job.damping}) __builtin_prefetch(p + at + kPrefetchSlots);
        const std::int32_t code = job.contiguous[e];
        if (code >= -1) {
          add_entry<false>(job, e, lane, code, x, v, f);
        } else {
          add_entry<true>(job, e, lane, -code - 2, x, v, f);
        }
      }
      for (int c = 0; c < 3; ++c) store(job.force[c] + i, load<V>(job.force[c] + i) + f.c[c]);
    }
  }
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
