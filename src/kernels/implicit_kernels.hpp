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
// spring network's layout (kernels::SpringJob).
template <class T>
struct SpringProductJob {
  const T* p[3];
  T* out[3];
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

// Bodies [begin, end): begin a multiple of kSpringSlice. Returns sum of p_i . out_i (double).
double spring_product(const SpringProductJob<float>& job, std::size_t begin, std::size_t end);
double spring_product(const SpringProductJob<double>& job, std::size_t begin, std::size_t end);

// x += alpha p, r -= alpha q, z = inv_diag r over [begin, end) of each of three arrays; adds
// r . z and r . r (double, summed as spring_product sums) to sums[0] and sums[1].
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

}  // namespace kinema::kernels
