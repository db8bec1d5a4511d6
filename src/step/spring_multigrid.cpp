#include "step/spring_multigrid.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "kernels/implicit_kernels.hpp"
#include "kernels/kernels.hpp"

namespace kinema {

using kernels::kSpringSlice;

namespace {

// Block Jacobi's damping in the V-cycle's sweeps. Each spring's term is at most twice its
// share of the two bodies' diagonal blocks, so A <= 2 B and the sweeps converge below 1; 0.7
// keeps a margin (0.9 took 10-14% fewer iterations than 0.6 on the cloths, measured before
// the coarse springs were scaled; Jacobi by components, whose bound is looser, failed at 0.7).
constexpr double kSmoothing = 0.7;
// A smooth error, constant over each aggregate, jumps between aggregates by about their width
// (3 bodies) times a body's difference, where only one spring in that width is stretched: the
// Galerkin edges overstate its energy about threefold a level, and the coarse correction
// falls that much short. Their springs are scaled down (the masses are exact): 1/2 measured
// best, between the chain's 1/3 and the cloth's.
constexpr double kCoarseStiffness = 0.5;
// Coarsening stops at this many nodes (or when a level no longer shrinks by 1.5), and a
// coarsest level of at most kCholeskyNodes is solved exactly.
constexpr std::size_t kCoarsestNodes = 48, kCholeskyNodes = 96, kMaxLevels = 16;

// Calls f(j, slot) for each spring slot of body i (its other end j != i), in layout order.
template <class T, class F>
void for_each_slot(const SpringNetwork<T>& net, std::size_t i, F&& f) {
  if (i >= net.covered) return;
  const std::size_t slice = i / kSpringSlice, lane = i % kSpringSlice;
  for (std::size_t e = net.slice_offset[slice]; e < net.slice_offset[slice + 1]; ++e) {
    const std::size_t at = e * kSpringSlice + lane, j = std::size_t(net.neighbor[at]);
    if (j != i) f(j, at);
  }
}

// A graph's aggregates, in node order: a node whose neighbours are all free starts one with
// them; a node left over joins the aggregate of its first neighbour that the first pass
// placed. Nodes without neighbours stay out (-1). neighbors(i, f) calls f(j) for each j != i.
template <class Neighbors>
std::vector<std::int32_t> aggregate_nodes(std::size_t n, Neighbors&& neighbors, std::size_t& count) {
  std::vector<std::int32_t> aggregate(n, -1);
  std::vector<unsigned char> linked(n, 0);
  count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    bool free = true;
    neighbors(i, [&](std::size_t j) { linked[i] = 1, free = free && aggregate[j] < 0; });
    if (!linked[i] || aggregate[i] >= 0 || !free) continue;
    const auto id = std::int32_t(count++);
    aggregate[i] = id;
    neighbors(i, [&](std::size_t j) { aggregate[j] = id; });
  }
  const std::vector<std::int32_t> first = aggregate;
  for (std::size_t i = 0; i < n; ++i) {
    if (!linked[i] || aggregate[i] >= 0) continue;
    neighbors(i, [&](std::size_t j) {
      if (aggregate[i] < 0) aggregate[i] = first[j];
    });
  }
  return aggregate;
}

std::int32_t find_edge(const std::vector<std::uint32_t>& row_offset, const std::vector<std::uint32_t>& column,
                       std::size_t row, std::size_t to) {
  const auto begin = column.begin() + row_offset[row], end = column.begin() + row_offset[row + 1];
  const auto at = std::lower_bound(begin, end, std::uint32_t(to));
  return at != end && *at == to ? std::int32_t(at - column.begin()) : -1;
}

std::size_t groups(std::size_t nodes) { return (nodes + kernels::kCoarseGroup - 1) / kernels::kCoarseGroup; }
// A block of nodes holds whole groups, so no two blocks write one group's values.
static_assert(kBlockBodies % kernels::kCoarseGroup == 0);

}  // namespace

// A coarse level's aggregates' members (ascending) and edges (each row's columns ascending)
// from the finer level's graph and aggregates.
template <class T>
template <class Neighbors>
typename SpringMultigrid<T>::Level SpringMultigrid<T>::make_level(const std::vector<std::int32_t>& aggregate,
                                                                  std::size_t count, Neighbors&& neighbors) {
  Level level;
  level.size = count;
  level.member_offset.assign(count + 1, 0);
  for (std::int32_t a : aggregate) {
    if (a >= 0) ++level.member_offset[std::size_t(a) + 1];
  }
  for (std::size_t k = 0; k < count; ++k) level.member_offset[k + 1] += level.member_offset[k];
  level.members.resize(level.member_offset[count]);
  std::vector<std::uint32_t> fill(level.member_offset.begin(), level.member_offset.end() - 1);
  for (std::size_t i = 0; i < aggregate.size(); ++i) {
    if (aggregate[i] >= 0) level.members[fill[std::size_t(aggregate[i])]++] = std::uint32_t(i);
  }
  std::vector<std::int32_t> seen(count, -1);
  level.row_offset.assign(1, 0);
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t start = level.column.size();
    for (std::uint32_t m = level.member_offset[k]; m < level.member_offset[k + 1]; ++m) {
      neighbors(level.members[m], [&](std::size_t j) {
        const std::int32_t to = aggregate[j];
        if (to >= 0 && std::size_t(to) != k && seen[std::size_t(to)] != std::int32_t(k)) {
          seen[std::size_t(to)] = std::int32_t(k), level.column.push_back(std::uint32_t(to));
        }
      });
    }
    std::sort(level.column.begin() + std::ptrdiff_t(start), level.column.end());
    level.row_offset.push_back(std::uint32_t(level.column.size()));
  }
  level.mirror.resize(level.column.size());
  for (std::size_t k = 0; k < count; ++k) {
    for (std::uint32_t e = level.row_offset[k]; e < level.row_offset[k + 1]; ++e) {
      level.mirror[e] = std::uint32_t(find_edge(level.row_offset, level.column, level.column[e], k));
    }
  }
  return level;
}

template <class T>
void SpringMultigrid<T>::build(const SpringNetwork<T>& net) {
  net_ = nullptr;  // until the levels are whole (an allocation may throw)
  levels_.clear();
  auto fine_neighbors = [&](std::size_t i, auto&& f) { for_each_slot(net, i, [&](std::size_t j, std::size_t) { f(j); }); };
  std::size_t count = 0;
  fine_aggregate_ = aggregate_nodes(net.covered, fine_neighbors, count);
  levels_.push_back(make_level(fine_aggregate_, count, fine_neighbors));
  slot_edge_.assign(net.neighbor.size(), -1);
  for (std::size_t i = 0; i < net.covered; ++i) {
    for_each_slot(net, i, [&](std::size_t j, std::size_t at) {
      const std::int32_t from = fine_aggregate_[i], to = fine_aggregate_[j];
      if (from != to) slot_edge_[at] = find_edge(levels_[0].row_offset, levels_[0].column, std::size_t(from), std::size_t(to));
    });
  }
  while (levels_.back().size > kCoarsestNodes && levels_.size() < kMaxLevels) {
    Level& finer = levels_.back();
    auto neighbors = [&finer](std::size_t i, auto&& f) {
      for (std::uint32_t e = finer.row_offset[i]; e < finer.row_offset[i + 1]; ++e) f(std::size_t(finer.column[e]));
    };
    std::vector<std::int32_t> aggregate = aggregate_nodes(finer.size, neighbors, count);
    if (count == 0 || 2 * finer.size < 3 * count) break;  // it no longer shrinks (or has no edges left)
    Level next = make_level(aggregate, count, neighbors);
    finer.edge_down.assign(finer.column.size(), -1);
    for (std::size_t i = 0; i < finer.size; ++i) {
      for (std::uint32_t e = finer.row_offset[i]; e < finer.row_offset[i + 1]; ++e) {
        const std::int32_t from = aggregate[i], to = aggregate[finer.column[e]];
        if (from != to) finer.edge_down[e] = find_edge(next.row_offset, next.column, std::size_t(from), std::size_t(to));
      }
    }
    finer.aggregate = std::move(aggregate);
    levels_.push_back(std::move(next));
  }
  for (Level& level : levels_) {
    const std::size_t padded = groups(level.size) * kernels::kCoarseGroup;
    level.diagonal.resize(padded), level.smoother.resize(level.size), level.edge.resize(level.column.size());
    level.b.resize(padded), level.x.resize(padded), level.t.resize(padded);
    lay_out_rows(level);
  }
  for (auto& a : correction_) a.assign(levels_[0].size + 1, T(0));
  net_ = &net, slots_ = net.neighbor.size();
}

// The fine level's arrays for sets padded to `padded` bodies: they only grow.
template <class T>
void SpringMultigrid<T>::reserve(std::size_t padded) {
  if (padded <= capacity_) return;
  for (auto* arrays : {&t_, &y_}) {
    for (auto& a : *arrays) a.resize(padded);
  }
  for (auto& a : block_) a.resize(padded);
  block_dots_.resize(block_count(padded));
  prolong_node_.resize(padded);
  capacity_ = padded;
}

template <class T>
std::size_t SpringMultigrid<T>::bytes() const {
  std::size_t total = (fine_aggregate_.capacity() + slot_edge_.capacity() + prolong_node_.capacity()) * sizeof(std::int32_t) +
                      12 * capacity_ * sizeof(T) + block_dots_.capacity() * sizeof(double) +
                      3 * correction_[0].capacity() * sizeof(T) + (cholesky_.capacity() + coarsest_y_.capacity()) * sizeof(double);
  for (const Level& l : levels_) {
    total += (l.member_offset.capacity() + l.members.capacity() + l.row_offset.capacity() + l.column.capacity() +
              l.mirror.capacity() + l.aggregate.capacity() + l.edge_down.capacity()) * 4;
    total += (l.diagonal.capacity() + l.edge.capacity() + l.smoother.capacity()) * sizeof(Sym3);
    total += (l.b.capacity() + l.x.capacity() + l.t.capacity()) * sizeof(Vec3);
    total += (l.group_row.capacity() + l.row_column.capacity()) * 4 + 6 * l.row_edge[0].capacity() * sizeof(double);
  }
  return total;
}

namespace {

template <class S>
void add_to(S& to, const S& from) {
  for (int k = 0; k < 6; ++k) to.a[k] += from.a[k];
}

// w u u^T + a I
template <class S>
S spring_block(double w, double a, const double u[3]) {
  return {{w * u[0] * u[0] + a, w * u[1] * u[1] + a, w * u[2] * u[2] + a, w * u[0] * u[1], w * u[0] * u[2],
           w * u[1] * u[2]}};
}

template <class S>
std::array<double, 3> times(const S& m, const std::array<double, 3>& x) {
  const double* a = m.a;
  return {a[0] * x[0] + a[3] * x[1] + a[4] * x[2], a[3] * x[0] + a[1] * x[1] + a[5] * x[2],
          a[4] * x[0] + a[5] * x[1] + a[2] * x[2]};
}

// The inverse of a symmetric positive definite 3x3 block; zero for one that is not (an
// aggregate of fixed bodies only).
template <class S>
S inverse(const S& m) {
  const double a = m.a[0], b = m.a[1], c = m.a[2], d = m.a[3], e = m.a[4], f = m.a[5];
  const double c00 = b * c - f * f, c11 = a * c - e * e, c22 = a * b - d * d;
  const double c01 = e * f - d * c, c02 = d * f - e * b, c12 = d * e - a * f;
  const double det = a * c00 + d * c01 + e * c02;
  if (!(det > 0) || !std::isfinite(det) || !(a > 0)) return {};
  return {{c00 / det, c11 / det, c22 / det, c01 / det, c02 / det, c12 / det}};
}

}  // namespace

// Level 0 from the fine system: each aggregate's masses and springs to fixed bodies (D), and
// per edge the springs from its members into the other aggregate (C), each summed from the
// lower-numbered end and copied to the other, so that the matrix is exactly symmetric.
template <class T>
void SpringMultigrid<T>::fine_galerkin(const FineSystem<T>& fine) {
  Level& level = levels_[0];
  std::fill(level.edge.begin(), level.edge.end(), Sym3{});
  for_nodes(level.size, [&](std::size_t k) {  // each node writes its own row
    Sym3 d{};
    for (std::uint32_t m = level.member_offset[k]; m < level.member_offset[k + 1]; ++m) {
      const std::size_t i = level.members[m];
      const double mass = double(fine.mass[i]);
      if (mass == 0) continue;
      d.a[0] += mass, d.a[1] += mass, d.a[2] += mass;
      for_each_slot(*net_, i, [&](std::size_t j, std::size_t at) {
        const std::int32_t e = slot_edge_[at];
        const bool anchor = fine.mass[j] == 0;
        if (!anchor && (e < 0 || level.column[std::size_t(e)] < k)) return;  // inside, or summed from the other end
        const double u[3] = {double(fine.unit[0][at]), double(fine.unit[1][at]), double(fine.unit[2][at])};
        add_to(anchor ? d : level.edge[std::size_t(e)], spring_block<Sym3>(-double(fine.along[at]), -double(fine.across[at]), u));
      });
    }
    level.diagonal[k] = d;
  });
  mirror_edges(level);
}

// The summed edges scaled by kCoarseStiffness, then each copied to its mirror.
template <class T>
void SpringMultigrid<T>::mirror_edges(Level& level) const {
  for_nodes(level.size, [&](std::size_t k) {
    for (std::uint32_t e = level.row_offset[k]; e < level.row_offset[k + 1]; ++e) {
      if (level.column[e] > k) {
        for (double& v : level.edge[e].a) v *= kCoarseStiffness;
      }
    }
  });
  for_nodes(level.size, [&](std::size_t k) {  // reads only edges the first pass finished
    for (std::uint32_t e = level.row_offset[k]; e < level.row_offset[k + 1]; ++e) {
      if (level.column[e] < k) level.edge[e] = level.edge[level.mirror[e]];
    }
  });
}

// Level l from level l - 1: the members' D summed, and their edges into other aggregates.
template <class T>
void SpringMultigrid<T>::coarse_galerkin(std::size_t l) {
  const Level& finer = levels_[l - 1];
  Level& level = levels_[l];
  std::fill(level.edge.begin(), level.edge.end(), Sym3{});
  for_nodes(level.size, [&](std::size_t k) {
    Sym3 d{};
    for (std::uint32_t m = level.member_offset[k]; m < level.member_offset[k + 1]; ++m) {
      const std::size_t i = level.members[m];
      add_to(d, finer.diagonal[i]);
      for (std::uint32_t e = finer.row_offset[i]; e < finer.row_offset[i + 1]; ++e) {
        const std::int32_t down = finer.edge_down[e];
        if (down >= 0 && level.column[std::size_t(down)] > k) add_to(level.edge[std::size_t(down)], finer.edge[e]);
      }
    }
    level.diagonal[k] = d;
  });
  mirror_edges(level);
}

template <class T>
void SpringMultigrid<T>::finish_level(Level& level) const {
  for_nodes(level.size, [&](std::size_t k) {
    Sym3 g = level.diagonal[k];
    for (std::uint32_t e = level.row_offset[k]; e < level.row_offset[k + 1]; ++e) add_to(g, level.edge[e]);
    level.smoother[k] = inverse(g);
  });
}

// The coarsest level's dense matrix, factored L L^T (lower, row-major). An unknown whose
// pivot vanishes (an aggregate of fixed bodies) is left out: its solution is 0.
template <class T>
void SpringMultigrid<T>::factor_coarsest() {
  const Level& level = levels_.back();
  cholesky_.clear(), dead_.clear();
  if (level.size > kCholeskyNodes) return;
  const std::size_t n = 3 * level.size;
  std::vector<double>& a = cholesky_;
  a.assign(n * n, 0.0);
  dead_.assign(n, 0);
  coarsest_y_.assign(n, 0.0);
  constexpr int row[6] = {0, 1, 2, 0, 0, 1}, col[6] = {0, 1, 2, 1, 2, 2};
  auto put = [&](std::size_t i, std::size_t j, const Sym3& s, double sign) {
    for (int k = 0; k < 6; ++k) {
      a[(3 * i + row[k]) * n + 3 * j + col[k]] += sign * s.a[k];
      if (row[k] != col[k]) a[(3 * i + col[k]) * n + 3 * j + row[k]] += sign * s.a[k];
    }
  };
  for (std::size_t i = 0; i < level.size; ++i) {
    put(i, i, level.diagonal[i], 1);
    for (std::uint32_t e = level.row_offset[i]; e < level.row_offset[i + 1]; ++e) {
      put(i, i, level.edge[e], 1);
      put(i, level.column[e], level.edge[e], -1);
    }
  }
  for (std::size_t k = 0; k < n; ++k) {
    const double scale = a[k * n + k];
    double s = scale;
    for (std::size_t p = 0; p < k; ++p) s -= a[k * n + p] * a[k * n + p];
    if (!(s > 1e-12 * scale)) {
      dead_[k] = 1;
      for (std::size_t i = k; i < n; ++i) a[i * n + k] = 0;
      continue;
    }
    const double pivot = std::sqrt(s);
    a[k * n + k] = pivot;
    for (std::size_t i = k + 1; i < n; ++i) {
      double v = a[i * n + k];
      for (std::size_t p = 0; p < k; ++p) v -= a[i * n + p] * a[k * n + p];
      a[i * n + k] = v / pivot;
    }
  }
}

template <class T>
void SpringMultigrid<T>::solve_coarsest(Level& level) {
  if (cholesky_.empty()) {  // a level that stopped shrinking: two damped sweeps
    for_nodes(level.size, [&](std::size_t k) { level.x[k] = scaled(level.smoother[k], level.b[k]); });
    residual(level, level.t);
    for_nodes(level.size, [&](std::size_t k) { add_scaled(level.x[k], level.smoother[k], level.t[k]); });
    return;
  }
  const std::size_t n = 3 * level.size;
  const std::vector<double>& a = cholesky_;
  std::vector<double>& y = coarsest_y_;  // sized with the factor: no allocation in a step
  for (std::size_t k = 0; k < n; ++k) {
    double v = level.b[k / 3][k % 3];
    for (std::size_t p = 0; p < k; ++p) v -= a[k * n + p] * y[p];
    y[k] = dead_[k] ? 0.0 : v / a[k * n + k];
  }
  for (std::size_t k = n; k-- > 0;) {
    double v = y[k];
    for (std::size_t i = k + 1; i < n; ++i) v -= a[i * n + k] * y[i];
    y[k] = dead_[k] ? 0.0 : v / a[k * n + k];
  }
  for (std::size_t k = 0; k < n; ++k) level.x[k / 3][k % 3] = y[k];
}

// The rows of each group of nodes: as many as its nodes' most edges; a lane past a node's
// edges (or past the last node) names its own node, with C = 0.
template <class T>
void SpringMultigrid<T>::lay_out_rows(Level& level) {
  constexpr std::size_t G = kernels::kCoarseGroup;
  const std::size_t n = groups(level.size);
  level.group_row.assign(n + 1, 0);
  for (std::size_t g = 0; g < n; ++g) {
    std::uint32_t rows = 0;
    for (std::size_t k = g * G; k < std::min(level.size, (g + 1) * G); ++k) rows = std::max(rows, level.row_offset[k + 1] - level.row_offset[k]);
    level.group_row[g + 1] = level.group_row[g] + rows;
  }
  level.row_column.resize(std::size_t(level.group_row[n]) * G);
  for (std::size_t g = 0; g < n; ++g) {
    for (std::uint32_t r = level.group_row[g]; r < level.group_row[g + 1]; ++r) {
      for (std::size_t l = 0; l < G; ++l) {
        const std::size_t k = g * G + l, e = k < level.size ? level.row_offset[k] + (r - level.group_row[g]) : 0;
        const bool has = k < level.size && e < level.row_offset[k + 1];
        assert(!has || level.column[e] != k);  // the kernel takes its own index for "no edge"
        level.row_column[r * G + l] = has ? level.column[e] : std::uint32_t(k);
      }
    }
  }
  for (auto& a : level.row_edge) a.assign(level.row_column.size(), 0.0);
}

// This step's C of each edge into its row and lane.
template <class T>
void SpringMultigrid<T>::fill_rows(Level& level) const {
  constexpr std::size_t G = kernels::kCoarseGroup;
  for_nodes(level.size, [&](std::size_t k) {
    const std::size_t first = level.group_row[k / G] * G + k % G;
    for (std::uint32_t e = level.row_offset[k]; e < level.row_offset[k + 1]; ++e) {
      const std::size_t at = first + (e - level.row_offset[k]) * G;
      for (int i = 0; i < 6; ++i) level.row_edge[i][at] = level.edge[e].a[i];
    }
  });
}

// out = b - A x, node by node as the kernel's groups (which read the blocks and vectors as
// arrays of doubles).
template <class T>
void SpringMultigrid<T>::residual(const Level& level, std::vector<Vec3>& out) const {
  static_assert(sizeof(Sym3) == 6 * sizeof(double) && sizeof(Vec3) == 3 * sizeof(double));
  if (level.size == 0) return;  // (the views below name a first element)
  const kernels::CoarseResidualJob job{level.group_row.data(),
                                       level.row_column.data(),
                                       {level.row_edge[0].data(), level.row_edge[1].data(), level.row_edge[2].data(),
                                        level.row_edge[3].data(), level.row_edge[4].data(), level.row_edge[5].data()},
                                       level.diagonal.data()->a,
                                       level.x.data()->data(),
                                       level.b.data()->data(),
                                       out.data()->data()};
  for_each_block(workers_, level.size, [&](Block b) { kernels::coarse_residual(job, b.begin, b.end); });
}

template <class T>
typename SpringMultigrid<T>::Vec3 SpringMultigrid<T>::scaled(const Sym3& inverse, const Vec3& v) {
  Vec3 y = times(inverse, v);
  for (double& c : y) c *= kSmoothing;
  return y;
}

template <class T>
void SpringMultigrid<T>::add_scaled(Vec3& x, const Sym3& inverse, const Vec3& v) {
  const Vec3 y = scaled(inverse, v);
  for (int d = 0; d < 3; ++d) x[d] += y[d];
}

// Each body's 3x3 diagonal block of the fine matrix, inverted: the fine level's smoother.
// (Jacobi by components sees a body's springs in every component it moves in; a body
// moving across its springs, as a curved cloth bends, is then smoothed as if it were held.)
template <class T>
void SpringMultigrid<T>::fine_blocks(const Workers& workers, const FineSystem<T>& fine) {
  const kernels::SmootherJob<T> job{fine.mass,
                                    net_->covered,
                                    net_->slice_offset.data(),
                                    {fine.unit[0], fine.unit[1], fine.unit[2]},
                                    fine.along,
                                    fine.across,
                                    kSmoothing,
                                    {block_[0].data(), block_[1].data(), block_[2].data(), block_[3].data(),
                                     block_[4].data(), block_[5].data()}};
  for_each_block(workers, padded_, [&](Block b) { kernels::smoother_blocks(job, b.begin, b.end); });
}

// out = base + the damped block inverse of `in` over block b (base null: 0).
template <class T>
void SpringMultigrid<T>::smooth(Block b, const T* const in[3], const T* const base[3], T* const out[3]) const {
  const kernels::BlockSmoothJob<T> job{{block_[0].data(), block_[1].data(), block_[2].data(), block_[3].data(),
                                        block_[4].data(), block_[5].data()},
                                       {in[0], in[1], in[2]},
                                       {base ? base[0] : nullptr, base ? base[1] : nullptr, base ? base[2] : nullptr},
                                       {out[0], out[1], out[2]}};
  kernels::block_smooth(job, b.begin, b.end);
}

template <class T>
void SpringMultigrid<T>::set_operator(const Workers& workers, const FineSystem<T>& fine, std::size_t padded) {
  reserve(padded);
  padded_ = padded, fine_ = fine, workers_ = workers;
  fine_blocks(workers, fine);
  const auto zero = std::int32_t(levels_[0].size);  // the correction's last value: 0
  for (std::size_t i = 0; i < padded_; ++i) {
    const std::int32_t k = i < fine_aggregate_.size() ? fine_aggregate_[i] : -1;
    prolong_node_[i] = k >= 0 && fine.mass[i] != 0 ? k : zero;
  }
  fine_galerkin(fine);
  finish_level(levels_[0]);
  for (std::size_t l = 1; l < levels_.size(); ++l) {
    coarse_galerkin(l);
    finish_level(levels_[l]);
  }
  factor_coarsest();
  // The residual's rows, where a residual is taken: not at a coarsest level solved exactly.
  const std::size_t with_residual = cholesky_.empty() ? levels_.size() : levels_.size() - 1;
  for (std::size_t l = 0; l < with_residual; ++l) fill_rows(levels_[l]);
}

// Coarse level l's V-cycle on its b, into its x.
template <class T>
void SpringMultigrid<T>::vcycle(std::size_t l) {
  Level& level = levels_[l];
  if (l + 1 == levels_.size()) return solve_coarsest(level);
  for_nodes(level.size, [&](std::size_t k) { level.x[k] = scaled(level.smoother[k], level.b[k]); });
  residual(level, level.t);
  Level& next = levels_[l + 1];
  for_nodes(next.size, [&](std::size_t k) {
    Vec3 sum{0, 0, 0};
    for (std::uint32_t m = next.member_offset[k]; m < next.member_offset[k + 1]; ++m) {
      for (int d = 0; d < 3; ++d) sum[d] += level.t[next.members[m]][d];
    }
    next.b[k] = sum;
  });
  vcycle(l + 1);
  for_nodes(level.size, [&](std::size_t k) {
    if (level.aggregate[k] < 0) return;
    for (int d = 0; d < 3; ++d) level.x[k][d] += next.x[std::size_t(level.aggregate[k])][d];
  });
  residual(level, level.t);
  for_nodes(level.size, [&](std::size_t k) { add_scaled(level.x[k], level.smoother[k], level.t[k]); });
}

// t_ = r - A y over block b (y is read at the block's bodies' neighbours too).
template <class T>
void SpringMultigrid<T>::fine_residual(Block b, const T* const r[3], const T* const y[3]) {
  const FineSystem<T>& f = fine_;
  T* const t[3] = {t_[0].data(), t_[1].data(), t_[2].data()};
  const kernels::SpringProductJob<T> job{{y[0], y[1], y[2]},
                                         {t[0], t[1], t[2]},
                                         {r[0], r[1], r[2]},
                                         f.mass,
                                         net_->covered,
                                         net_->slice_offset.data(),
                                         net_->neighbor.data(),
                                         net_->contiguous.data(),
                                         {f.unit[0], f.unit[1], f.unit[2]},
                                         f.along,
                                         f.across,
                                         T(1)};
  kernels::spring_product(job, b.begin, b.end);
}

// y = S r; the residual to level 0; its V-cycle; y += P x; z = y + S (r - A y); r . z, summed
// per block, then over the blocks in order. y is its own array: the last pass reads it at
// other blocks' bodies while writing z.
template <class T>
double SpringMultigrid<T>::apply(const Workers& workers, const T* const r[3], T* const z[3]) {
  workers_ = workers;
  const FineSystem<T>& f = fine_;
  T* const y[3] = {y_[0].data(), y_[1].data(), y_[2].data()};
  const T* const t[3] = {t_[0].data(), t_[1].data(), t_[2].data()};
  for_each_block(workers, padded_, [&](Block b) { smooth(b, r, nullptr, y); });
  for_each_block(workers, padded_, [&](Block b) { fine_residual(b, r, y); });
  Level& first = levels_[0];
  for_nodes(first.size, [&](std::size_t k) {
    Vec3 sum{0, 0, 0};
    for (std::uint32_t m = first.member_offset[k]; m < first.member_offset[k + 1]; ++m) {
      const std::size_t i = first.members[m];
      if (f.mass[i] == 0) continue;
      for (int d = 0; d < 3; ++d) sum[d] += double(t[d][i]);
    }
    first.b[k] = sum;
  });
  vcycle(0);
  for_nodes(first.size, [&](std::size_t k) {
    for (int d = 0; d < 3; ++d) correction_[d][k] = T(first.x[k][d]);
  });
  const kernels::ProlongJob<T> prolong{prolong_node_.data(),
                                       {correction_[0].data(), correction_[1].data(), correction_[2].data()},
                                       {y[0], y[1], y[2]}};
  for_each_block(workers, padded_, [&](Block b) { kernels::prolong_add(prolong, b.begin, b.end); });
  const T* const zr[3] = {z[0], z[1], z[2]};
  for_each_block(workers, padded_, [&](Block b) {
    fine_residual(b, r, y);
    smooth(b, t, y, z);
    block_dots_[b.begin / kBlockBodies] = kernels::dot3(r, zr, b.begin, b.end);
  });
  double total = 0;
  for (std::size_t k = 0; k < block_count(padded_); ++k) total += block_dots_[k];
  return total;
}

template class SpringMultigrid<float>;
template class SpringMultigrid<double>;

}  // namespace kinema
