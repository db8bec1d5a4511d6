#pragma once
// Aggregation multigrid: the implicit path's preconditioner for large spring networks
// (src/step/implicit_path.hpp; ImplicitPreconditioner in kinema/stepper.hpp). Jacobi's
// conjugate gradients need iterations in proportion to gamma h |lambda| (the matrix's
// condition number grows as its square); one V-cycle of this preconditioner costs two more
// products an iteration and takes most stiff modes out of that count.
//
// The network's bodies are grouped into aggregates (in body order, a body with every
// neighbour not yet taken: 3 x 3 patches of a grid), those into aggregates again, down to a
// few dozen. Each coarse level's matrix is the Galerkin product P^T A P with P constant over
// an aggregate and zero at fixed bodies, which keeps the form of the fine one: per node a
// symmetric 3x3 block D (the masses, the springs to fixed bodies) and per edge a symmetric
// 3x3 block C (the springs that cross between two aggregates; those inside one cancel):
//   (A x)_I = D_I x_I + sum_J C_IJ (x_I - x_J),
// with C scaled by kCoarseStiffness (the .cpp says why). One V-cycle: damped block Jacobi
// before and after each coarse correction, a Cholesky solve at the coarsest level; symmetric
// and positive definite, as conjugate gradients needs. The coarse levels are in double, each
// pass over nodes computing each node's values alone; every pass is blocks of the job system:
// the bits depend on neither the thread count nor the instruction set.

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "forces/coupled_forces.hpp"
#include "kinema/bodies.hpp"
#include "parallel/blocks.hpp"

namespace kinema {

// The fine level as the implicit path holds it for a step, over the network the levels were
// built for: A p = m p + sum over each body's slots of along u (u . dp) + across dp,
// dp = p_j - p_i (fixed bodies: rows and columns left out).
template <class T>
struct FineSystem {
  const T* mass;  // 0 for fixed bodies
  const T* unit[3];
  const T* along;
  const T* across;
};

template <class T>
class SpringMultigrid {
 public:
  // The aggregates of `net` (laid out): once per layout, whatever the sets stepped.
  void build(const SpringNetwork<T>& net);
  bool built_for(const SpringNetwork<T>& net) const { return net_ == &net && slots_ == net.neighbor.size(); }
  std::size_t bytes() const;
  // The coarse levels' matrices for this step's fine one (which must outlive the V-cycles),
  // over a set padded to `padded` bodies (the fine arrays grow to the largest seen).
  void set_operator(const Workers& workers, const FineSystem<T>& fine, std::size_t padded);
  // z = one V-cycle applied to r; returns r . z (the same sum on every thread count).
  double apply(const Workers& workers, const T* const r[3], T* const z[3]);

 private:
  using Vec3 = std::array<double, 3>;
  struct Sym3 {  // xx, yy, zz, xy, xz, yz
    double a[6];
  };
  struct Level {
    std::size_t size = 0;
    std::vector<std::uint32_t> member_offset, members;  // the finer level's nodes in each, ascending
    std::vector<std::uint32_t> row_offset, column, mirror;  // edges both ways; mirror: the other way's
    std::vector<std::int32_t> aggregate;  // each node's in the next level (-1: none)
    std::vector<std::int32_t> edge_down;  // each edge's in the next level (-1: inside an aggregate)
    std::vector<Sym3> diagonal, edge, smoother;  // D, C, the inverse of D + sum C (per step)
    std::vector<Vec3> b, x, t;  // b, x, t and diagonal padded to whole groups
    // The residual's layout (kernels::CoarseResidualJob): each group's first row, each row's
    // columns, and C's six entries per row and lane (per step).
    std::vector<std::uint32_t> group_row, row_column;
    std::array<std::vector<double>, 6> row_edge;
  };

  template <class Neighbors>
  static Level make_level(const std::vector<std::int32_t>& aggregate, std::size_t count, Neighbors&& neighbors);
  void mirror_edges(Level& level) const;
  static void lay_out_rows(Level& level);
  void fill_rows(Level& level) const;
  static Vec3 scaled(const Sym3& inverse, const Vec3& v);  // the damped sweep's step
  static void add_scaled(Vec3& x, const Sym3& inverse, const Vec3& v);
  void reserve(std::size_t padded);
  void fine_galerkin(const FineSystem<T>& fine);
  void fine_blocks(const Workers& workers, const FineSystem<T>& fine);
  void smooth(Block b, const T* const in[3], const T* const base[3], T* const out[3]) const;
  void coarse_galerkin(std::size_t l);
  void finish_level(Level& level) const;
  // fn(k) for each of n nodes, as blocks of this call's workers: each node writes only its
  // own values, so any split gives the same bits.
  template <class F>
  void for_nodes(std::size_t n, F&& fn) const {
    for_each_block(workers_, n, [&](Block b) {
      for (std::size_t k = b.begin; k < b.end; ++k) fn(k);
    });
  }
  void factor_coarsest();
  void solve_coarsest(Level& level);
  void vcycle(std::size_t l);
  void residual(const Level& level, std::vector<Vec3>& out) const;  // out = b - A x
  void fine_residual(Block b, const T* const r[3], const T* const y[3]);

  const SpringNetwork<T>* net_ = nullptr;
  std::size_t slots_ = 0;
  std::size_t capacity_ = 0, padded_ = 0;     // the fine arrays' length; this step's set's
  std::vector<std::int32_t> fine_aggregate_;  // each covered body's level-0 node (-1: no springs)
  std::vector<std::int32_t> slot_edge_;       // each slot's level-0 edge (-1: none)
  std::vector<Level> levels_;                 // 0: the first coarse level
  std::vector<double> cholesky_;              // the coarsest level's factor, dense, or empty
  std::vector<double> coarsest_y_;            // its solve's unknowns
  std::vector<unsigned char> dead_;           // unknowns of the coarsest level left out (no mass)
  FineSystem<T> fine_{};
  Workers workers_{};                         // this call's
  std::array<AlignedArray<T>, 6> block_;    // the fine smoother: xx yy zz xy xz yz per body
  std::array<AlignedArray<T>, 3> y_;          // the fine level's iterate
  std::vector<double> block_dots_;
  std::vector<std::int32_t> prolong_node_;    // each body's level-0 node, or the zero past them
  std::array<std::vector<T>, 3> correction_;  // level 0's x in T, and a zero
  std::array<AlignedArray<T>, 3> t_;          // the fine level's residual
};

extern template class SpringMultigrid<float>;
extern template class SpringMultigrid<double>;

}  // namespace kinema
