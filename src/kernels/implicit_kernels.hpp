#pragma once
// The implicit path's passes over a block (src/step/implicit_path.hpp): the product with the
// springs' system matrix and the conjugate-gradient update. Each is compiled once per
// instruction set (kernels/cloned.hpp) from loops over a slice's lanes that every clone
// vectorizes its own way with the same operations per body, so the bits are the same on
// every CPU; dot products are summed in double, a running sum per lane of a slice over the
// slices in order, then the lanes in order.

#include <cstddef>
#include <cstdint>

namespace kinema::kernels {

// out_i = cm m_i p_i + sum over body i's spring slots (in layout order) of
//   along u (u . dp) + across dp,   dp = p_j - p_i,
// and 0 for bodies of mass 0, with `along` and `across` per slot (the caller's weights of the
// stiffness and damping along the spring and of the stiffness across it). The slots are the
// spring network's layout (kernels::SpringJob). With `minuend` (else null), out = minuend -
// that instead: a residual in the same pass.
template <class T>
struct SpringProductJob {
  const T* p[3];
  T* out[3];
  const T* minuend[3];
  const T* mass;
  std::size_t covered;
  const std::uint32_t* slice_offset;
  const std::int32_t* neighbor;
  const std::int32_t* contiguous;
  const T* unit[3];
  const T* along;
  const T* across;
  T cm;
};

// Bodies [begin, end): begin a multiple of kSpringSlice. Returns sum of p_i . out_i (double;
// 0 with a minuend).
double spring_product(const SpringProductJob<float>& job, std::size_t begin, std::size_t end);
double spring_product(const SpringProductJob<double>& job, std::size_t begin, std::size_t end);

// x += alpha p, r -= alpha q, z = inv_diag r over [begin, end) of each of three arrays; adds
// r . z and r . r (double, summed as spring_product sums) to sums[0] and sums[1]. z null
// (another preconditioner makes it): neither z nor r . z.
template <class T>
struct CgUpdateJob {
  T* x[3];
  T* r[3];
  T* z[3];
  const T* p[3];
  const T* q[3];
  const T* inv_diag[3];
  T alpha;
};
void cg_update(const CgUpdateJob<float>& job, std::size_t begin, std::size_t end, double sums[2]);
void cg_update(const CgUpdateJob<double>& job, std::size_t begin, std::size_t end, double sums[2]);

// p = z + beta p over [begin, end) of each of three arrays: the next search direction.
template <class T>
struct CgDirectionJob {
  T* p[3];
  const T* z[3];
  T beta;
};
void cg_direction(const CgDirectionJob<float>& job, std::size_t begin, std::size_t end);
void cg_direction(const CgDirectionJob<double>& job, std::size_t begin, std::size_t end);

// Each spring slot's unit vector toward its other end at positions x, its stiffness along it
// (k (1 - g)) and across (k g), g = max(0, 1 - rest / length), and the system's weights along
// (sc damping + sk k_along) and across (sk k_across); each body's diagonal loses its slots'
// weights, in layout order. Bodies [begin, end), begin a multiple of kSpringSlice.
template <class T>
struct JacobianJob {
  const T* x[3];
  std::size_t covered;
  const std::uint32_t* slice_offset;
  const std::int32_t* neighbor;
  const T* rest;
  const T* k;
  const T* damping;
  T sc, sk;
  T* unit[3];
  T* k_along;
  T* k_across;
  T* a_along;
  T* a_across;
  T* diag[3];
};
void spring_jacobian(const JacobianJob<float>& job, std::size_t begin, std::size_t end);
void spring_jacobian(const JacobianJob<double>& job, std::size_t begin, std::size_t end);

// The multigrid preconditioner's fine passes (src/step/spring_multigrid.hpp), over
// [begin, end) of each of three arrays.
// Each body's 3x3 diagonal block of the system (mass, and per slot in layout order
// -(along u u^T + across I)), in double, inverted and scaled into block (xx yy zz xy xz yz);
// zero for bodies of mass 0 and blocks that are not positive definite.
template <class T>
struct SmootherJob {
  const T* mass;
  std::size_t covered;
  const std::uint32_t* slice_offset;
  const T* unit[3];
  const T* along;
  const T* across;
  double scale;
  T* block[6];
};
void smoother_blocks(const SmootherJob<float>& job, std::size_t begin, std::size_t end);
void smoother_blocks(const SmootherJob<double>& job, std::size_t begin, std::size_t end);

// out = base + B in, B a symmetric 3x3 block per body (xx yy zz xy xz yz); base null: 0.
template <class T>
struct BlockSmoothJob {
  const T* block[6];
  const T* in[3];
  const T* base[3];
  T* out[3];
};
void block_smooth(const BlockSmoothJob<float>& job, std::size_t begin, std::size_t end);
void block_smooth(const BlockSmoothJob<double>& job, std::size_t begin, std::size_t end);

// out_i += values[node_i] (node_i indexes a zero for bodies outside every aggregate).
template <class T>
struct ProlongJob {
  const std::int32_t* node;
  const T* values[3];
  T* out[3];
};
void prolong_add(const ProlongJob<float>& job, std::size_t begin, std::size_t end);
void prolong_add(const ProlongJob<double>& job, std::size_t begin, std::size_t end);

// A coarse level's residual out = b - A x (src/step/spring_multigrid.hpp), its nodes in groups
// of kCoarseGroup, each group's edges in rows: row r holds the r-th edge of each node (in the
// node's order), the node's own index where it has fewer. Per node, in order:
//   y = D x_k, then y += C (x_k - x_j) for each edge, out = b - y,
// D and C symmetric 3x3 (xx yy zz xy xz yz); x, b and out three doubles a node, D six.
inline constexpr std::size_t kCoarseGroup = 8;
struct CoarseResidualJob {
  const std::uint32_t* group_row;  // each group's first row; group g's rows end at group_row[g + 1]
  const std::uint32_t* column;     // kCoarseGroup per row
  const double* edge[6];           // kCoarseGroup per row, each of the six entries
  const double* diagonal;
  const double* x;
  const double* b;
  double* out;
};
// Nodes [begin, end): begin a multiple of kCoarseGroup; x, b and out hold whole groups.
void coarse_residual(const CoarseResidualJob& job, std::size_t begin, std::size_t end);

// a . b in double, summed as spring_product sums (a running sum per lane over the slices).
double dot3(const float* const a[3], const float* const b[3], std::size_t begin, std::size_t end);
double dot3(const double* const a[3], const double* const b[3], std::size_t begin, std::size_t end);

}  // namespace kinema::kernels
