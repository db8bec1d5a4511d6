#pragma once
// The implicit path: linearly implicit (Rosenbrock-W) steps for particle sets, the springs'
// Jacobian in the linear systems, every other force explicit (IMEX).
//
// Each stage's system (I - gamma h J) k = r, with y = (x, v), r = (r_x, r_v) and J taking
// positions to the springs' forces (K) and velocities to their dampers' (D), reduces to one
// for the velocity part alone:
//   (M - gamma h D - (gamma h)^2 K) k_v = M r_v + gamma h K r_x,   k_x = r_x + gamma h k_v.
// Its matrix is symmetric and, with the geometric stiffness kept for stretched springs
// only, positive definite: preconditioned conjugate gradients, matrix-free, its
// products summed per body over the spring network's slots in their fixed order; the
// preconditioner is each body's diagonal (Jacobi) or a multigrid V-cycle
// (src/step/spring_multigrid.hpp). Bodies
// with inv_mass 0 keep k_v = 0 (their rows are left out). Dot products are summed per block,
// then over the blocks in order: the bits depend on neither threads nor instruction set
// (this path's arithmetic is plain C++, one rounding per operation, no fused multiply-add).

#include <array>
#include <cstddef>
#include <vector>

#include "forces/coupled_forces.hpp"
#include "forces/force_lowering.hpp"
#include "kernels/implicit_kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"
#include "kinema/methods.hpp"
#include "kinema/stepper.hpp"
#include "parallel/blocks.hpp"
#include "step/spring_multigrid.hpp"
#include "step/staged_path.hpp"
#include "step/step_context.hpp"

namespace kinema {

template <class T>
class ImplicitPath {
 public:
  // Keeps references: every argument must outlive the path.
  ImplicitPath(const ForceModel<T>& forces, const Method& method, const kernels::KernelTable<T>& table,
               const LoweredForces<T>& lowered, const StepperOptions& options);

  void reserve(std::size_t padded);
  std::size_t capacity() const { return capacity_; }
  std::size_t bytes() const;
  // One step. Whatever throws (a callback, a stop request) leaves the bodies as they were.
  void step(const StepContext<T>& c);
  // Counts since the path was made, of the steps completed.
  const ImplicitStats& stats() const { return stats_; }

 private:
  using Vec3s = std::array<AlignedArray<T>, 3>;
  struct Solve;  // one conjugate-gradient solve's scalars

  void save_start(const StepContext<T>& c);
  void restore_start(const StepContext<T>& c);
  void build_jacobian(const StepContext<T>& c);
  void evaluate_stage(const StepContext<T>& c, int s);
  void solve_stage(const StepContext<T>& c, int s);
  void finish(const StepContext<T>& c);
  // The product (kernels/implicit_kernels.hpp): out = cm M p + (the slots' weights along and across) p over block b; returns p . out.
  double product(Block b, const T* const p[3], T* const out[3], T cm, const T* along, const T* across) const;
  void conjugate_gradients(const StepContext<T>& c, Vec3s& x);
  // z = the multigrid V-cycle of r; returns r . z.
  double precondition(const StepContext<T>& c);
  void take_preconditioned(const StepContext<T>& c, Vec3s& x);
  static bool all_finite(const T* const* v, std::size_t n);  // of three arrays' first n
  static bool all_finite(const Vec3s& v, std::size_t n);
  // A solve whose right side is finite but whose sums overflow T: refused by name.
  [[noreturn]] void overflows() const;
  // Runs pass(block, sums) over every block, each adding two partial sums; returns their
  // totals, added in block order.
  template <class Pass>
  std::array<double, 2> sum_blocks(const StepContext<T>& c, Pass&& pass);

  const Method& method_;
  const SpringNetwork<T>& net_;
  StagedPath<T> rates_;  // Euler's stage 0: the accelerations at the bodies' state
  double tolerance_;
  int max_iterations_;
  std::size_t capacity_ = 0;
  T gh_ = 0;  // gamma h of this step

  Vec3s x0_, v0_;                                    // where the step started
  std::array<Vec3s, kMaxRosenbrockStages> kx_, kv_;  // the stages' k
  Vec3s rx_, rhs_, r_, z_, p_, q_, inv_diag_;        // a stage's right side and CG's vectors
  AlignedArray<T> mass_;                             // 1 / inv_mass, 0 for fixed bodies
  // Per spring slot (the network's layout): the unit vector toward the other end, the
  // stiffness along it (k (1 - g)) and across (k g), g = max(0, 1 - rest / length), and the
  // system matrix's weights along (-gamma h damping - (gamma h)^2 k_along) and across
  // (-(gamma h)^2 k_across).
  Vec3s unit_;
  AlignedArray<T> k_along_, k_across_, a_along_, a_across_;
  std::vector<double> block_sums_[2];
  SpringMultigrid<T> multigrid_;
  ImplicitPreconditioner preconditioner_;
  bool use_multigrid_ = false;  // takes_multigrid: else Jacobi
  ImplicitStats stats_, step_stats_;  // since the path was made; in the step under way
};

extern template class ImplicitPath<float>;
extern template class ImplicitPath<double>;

}  // namespace kinema
