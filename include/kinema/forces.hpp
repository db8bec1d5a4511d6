#pragma once
// Force terms and the ForceModel that sums them.
//
// Local terms depend on one body's own state only; a model made of local terms alone is
// stepped by the fused single-pass kernels. Callbacks (user code over a slice of bodies)
// take the block path: every stage of a slice in cache, the callbacks between stages.
// Coupled terms (forces between bodies) take the staged path: one pass per stage, all
// bodies' stage state in memory.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "kinema/bodies.hpp"

namespace kinema {

// Uniform acceleration g (acts on every body with inv_mass > 0, whatever its mass).
struct Gravity {
  Vec3<double> g{0, -9.81, 0};
};
// F = -k v
struct LinearDrag {
  double k = 0;
};
// F = -k |v| v
struct QuadraticDrag {
  double k = 0;
};
// F = -k (x - anchor) - damping v
struct Spring {
  Vec3<double> anchor{};
  double k = 0;
  double damping = 0;
};
// a = -mu r / |r|^3 with r = x - center (mu: gravitational parameter G M). A dynamic body
// exactly at the centre has no defined pull: its step is NaN (FiniteGuard::check names it;
// scenes refuse such a body).
struct Central {
  Vec3<double> center{};
  double mu = 0;
};

// Rotational terms act on rigid bodies only (particles have no orientation):
// a constant world torque,
struct Torque {
  Vec3<double> torque{};
};
// torque = -c omega,
struct AngularDrag {
  double c = 0;
};
// a constant world force applied at a body-fixed point (body frame, from the centre of
// mass): it accelerates the centre of mass and gives the torque (R point) x force.
struct PointForce {
  Vec3<double> point{};
  Vec3<double> force{};
};
// a body-fixed point (body frame, from the centre of mass) held to a world anchor by a
// damped spring: with P = x + R point and V = v + omega x (R point) its world position and
// velocity, the force F = -k (P - anchor) - damping V at P (on the centre, and the torque
// (R point) x F). A top held at its tip, a pendulum at its pivot. It takes the rigid block
// path (its force turns with the body).
struct PointSpring {
  Vec3<double> point{};
  Vec3<double> anchor{};
  double k = 0;
  double damping = 0;
};

// Coupled terms: forces between the bodies of a set. They take the staged path (rigid
// bodies: the rigid path's staged passes). N-body gravity, spring pairs and CoupledTerms
// act on particles and on rigid bodies' centres; body springs on rigid bodies only.
//
// Softened Newtonian gravity among all bodies:
//   a_i = G sum_{j != i} m_j (x_j - x_i) / (|x_j - x_i|^2 + softening^2)^(3/2).
// A direct sum, each body's over the sources in index order, so the bits are the same on
// every instruction set and thread count. Bodies with inv_mass 0 (kinematic, padding)
// neither attract nor are pulled. Two bodies at the same point exert no force on each
// other (the direction is undefined; with softening 0 the magnitude too).
// fast (float sets; double sets always sum exactly): every other SIMD lane group of
// bodies takes each pair's r^-3 from the CPU's approximate reciprocal square root and one
// correction instead of an exact root and a division, so that the FMA pipes and the
// divider work at once: 1.36x the interactions per second with AVX-512 on Zen 4, 1.10x
// with AVX2, and 0.94x with SSE2, whose FMA is emulated (bench/README.md). There, two
// distinct bodies closer than about 1e-23 (their squared distance underflows) may pull each
// other by the softened formula rather than count as one point. Each pair's pull is then within 1e-6 of its
// exact value, relative, on AVX-512 and the scalar path, and within 2e-6 on SSE2 and AVX2
// (the exact kernel: 5e-7). The bits are the same on every thread count and job system;
// unlike the exact sums they differ between instruction sets and may differ between CPU
// models (the approximation instruction is the CPU's own). Bodies at one point with softening
// 0 stay together under the exact sums; under fast, two of them in differently computed lane
// groups are pulled a rounding apart, and the pull between them then grows without bound:
// give fast a softening where bodies may meet. A pair too far apart for its squared distance
// (it overflows float, past about 1.8e19) pulls by about 0, as under the exact sums.
struct NBody {
  double G = 1;
  double softening = 0;
  bool fast = false;
};

// A spring between bodies i and j (i != j) with a damper along it; with d = x_i - x_j,
//   F_i = -k (|d| - rest) d/|d| - damping ((v_i - v_j) . d/|d|) d/|d| = -F_j.
// Coincident ends exert no force (the direction is undefined).
struct SpringPair {
  std::uint32_t i = 0, j = 0;
  double rest = 0;     // rest length, finite and >= 0
  double k = 0;        // stiffness, finite and >= 0
  double damping = 0;  // finite and >= 0
};
// A network of springs. Each body sums its springs in an order fixed when a stepper is
// built (by neighbour offset where that lets the kernels load neighbours as one vector, else
// as added), so the bits do not depend on threads or instruction sets. Bodies may not have
// more than kMaxSpringsPerBody springs each, indices stay below kMaxSpringBodies and a
// model holds fewer than kMaxSpringPairs pairs.
struct Springs {
  std::vector<SpringPair> pairs;
};
// The bodies a set of spring pairs reaches: its largest index + 1 (0 without pairs).
inline std::size_t network_reach(std::span<const SpringPair> pairs) {
  std::size_t reach = 0;
  for (const SpringPair& p : pairs) reach = std::max({reach, std::size_t(p.i) + 1, std::size_t(p.j) + 1});
  return reach;
}
inline constexpr std::size_t kMaxSpringBodies = std::size_t(1) << 30;
inline constexpr std::size_t kMaxSpringsPerBody = 1024;
inline constexpr std::size_t kMaxSpringPairs = std::size_t(1) << 31;

// A damped spring between points of rigid bodies i and j (i != j), each point in its body's
// frame from its centre of mass. With P the points' world positions, V their world velocities
// (v + omega x (R point)) and d = P_i - P_j,
//   F_i = -k (|d| - rest) d/|d| - damping ((V_i - V_j) . d/|d|) d/|d| = -F_j,
// each at its point: the torques (R point_i) x F_i and (R point_j) x F_j. Coincident points
// exert no force. Each body sums its springs in the order added and F_j is the exact
// negation of F_i, so action equals reaction to the bit and the bits do not depend on
// threads or instruction sets. A kinematic body (inv_mass 0) is an anchor that moves on its
// own; particles ignore body springs.
struct BodySpring {
  std::uint32_t i = 0, j = 0;
  Vec3<double> point_i{}, point_j{};
  double rest = 0;     // finite and >= 0
  double k = 0;        // finite and >= 0
  double damping = 0;  // finite and >= 0
};
struct BodySprings {
  std::vector<BodySpring> springs;
};

using LocalTerm = std::variant<Gravity, LinearDrag, QuadraticDrag, Spring, Central, Torque,
                               AngularDrag, PointForce, PointSpring>;

// At most this many central attractors, and point forces, per model (they are evaluated
// in registers).
inline constexpr int kMaxCentralTerms = 4;
inline constexpr int kMaxPointForces = 4;

// What a callback or coupled term sees: the bodies [begin, begin + count) of one slice of a
// block (at most kBlockBodies) at one stage, as SoA pointers already offset to `begin`. It adds forces into fx, fy, fz
// (zeroed before the call); they are divided by mass afterwards. Counts include the inert
// padding bodies at the end of the set (at the origin, inv_mass 0); forces on them are
// ignored. `mass` is 1 / inv_mass, and 0 where inv_mass is 0 (kinematic and padding bodies):
// a force that grows with mass (gravity, fy[i] += g * mass[i]) needs no division per body.
//
// Every array of a view is its own (none overlaps another), and its pointers say so
// (__restrict): a callback that takes the view by value, [](kinema::ParticleBlock<float> b),
// lets the compiler vectorize its loop, where one that takes it by reference has it assume
// that a store to fx may change the view or the arrays it reads.
template <class T>
struct ParticleBlock {
  std::size_t begin = 0;
  std::size_t count = 0;
  double t = 0;
  const T *__restrict px, *__restrict py, *__restrict pz, *__restrict vx, *__restrict vy, *__restrict vz,
      *__restrict inv_mass, *__restrict mass;
  T *__restrict fx, *__restrict fy, *__restrict fz;
};

// A user force over a block; must be safe to call concurrently for different blocks.
//
// The contract the block path relies on (for ForceCallback and RigidCallback alike): a
// callback is a pure function of its block's view, the time and the user's own read-only
// data. It sees only its block, may be called for the blocks in any order and on any thread,
// writes only its block's outputs, and gives the same forces for the same view (a call may be
// repeated: after a throw, the steps before the one that threw are taken again). Then every
// stage of a block can run while the block is in cache, and the bits do not depend on threads.
template <class T>
using ForceCallback = std::function<void(const ParticleBlock<T>&)>;

// What a rigid-body callback sees: the bodies [begin, begin + count) of one block at one
// stage, as SoA pointers offset to `begin`: centre position and velocity, orientation
// quaternion (w, x, y, z; at a stage it may be off unit length by the step's error, and
// rotates as q / |q|), world angular velocity and world angular momentum, inverse mass and
// inverse principal moments. It adds a world force (at the centre of mass) into fx, fy, fz
// and a world torque into tx, ty, tz, zeroed before the call. Padding bodies (inv_mass 0)
// ignore both, as kinematic bodies do. `mass` is a ParticleBlock's: 1 / inv_mass, 0 where
// inv_mass is 0.
// Its arrays are its own, as a ParticleBlock's: take it by value to vectorize.
template <class T>
struct RigidBlock {
  std::size_t begin = 0;
  std::size_t count = 0;
  double t = 0;
  const T *__restrict px, *__restrict py, *__restrict pz, *__restrict vx, *__restrict vy, *__restrict vz;
  const T *__restrict qw, *__restrict qx, *__restrict qy, *__restrict qz;
  const T *__restrict wx, *__restrict wy, *__restrict wz;
  const T *__restrict lx, *__restrict ly, *__restrict lz;
  const T *__restrict inv_mass, *__restrict mass, *__restrict inv_ix, *__restrict inv_iy, *__restrict inv_iz;
  T *__restrict fx, *__restrict fy, *__restrict fz;
  T *__restrict tx, *__restrict ty, *__restrict tz;
};

// A user force and torque on rigid bodies, called once per stage (or kick) per block, for
// every method; the contract is ForceCallback's. Particles ignore it (and rigid bodies a
// ForceCallback), as they ignore torques.
template <class T>
using RigidCallback = std::function<void(const RigidBlock<T>&)>;

// The state of all bodies at one stage, for coupled terms.
template <class T>
struct ParticleState {
  std::size_t count = 0;  // padded size
  const T *px, *py, *pz, *vx, *vy, *vz, *inv_mass;
};

// A force that couples bodies. `accumulate` adds the forces on the bodies of `block`
// caused by all bodies in `all`; it is called concurrently for different blocks and must
// sum in an order that does not depend on the thread running it.
template <class T>
class CoupledTerm {
 public:
  virtual ~CoupledTerm() = default;
  virtual void accumulate(const ParticleState<T>& all, const ParticleBlock<T>& block) const = 0;
  virtual double potential_energy(const ParticleState<T>& all) const = 0;
};

template <class T>
class ForceModel {
 public:
  // Throws kinema::Error naming the term and field when a parameter is out of range.
  ForceModel& add(const LocalTerm& term);
  ForceModel& add(ForceCallback<T> callback);
  ForceModel& add(RigidCallback<T> callback);
  ForceModel& add(std::shared_ptr<const CoupledTerm<T>> term);
  // At most one NBody per model.
  ForceModel& add(const NBody& term);
  // Joins the model's network; a pair that repeats one already there (either order) is
  // refused, naming both.
  ForceModel& add(const Springs& term);
  ForceModel& add(Springs&& term);  // the first network's pairs move in, uncopied
  // Joins the model's body springs (the same limits as spring pairs).
  ForceModel& add(const BodySprings& term);

  std::span<const LocalTerm> local_terms() const { return local_; }
  std::span<const ForceCallback<T>> callbacks() const { return callbacks_; }
  std::span<const RigidCallback<T>> rigid_callbacks() const { return rigid_callbacks_; }
  std::span<const std::shared_ptr<const CoupledTerm<T>>> coupled_terms() const { return coupled_; }
  const std::optional<NBody>& nbody() const { return nbody_; }
  std::span<const SpringPair> springs() const { return springs_; }
  std::span<const BodySpring> body_springs() const { return body_springs_; }
  // True when the model couples particles: N-body gravity, springs or a CoupledTerm.
  bool coupled() const { return nbody_ || !springs_.empty() || !coupled_.empty(); }
  // True when it couples rigid bodies: those, or body springs.
  bool couples_rigid() const { return coupled() || !body_springs_.empty(); }
  // True when every term is local and built in: the fused path applies (to particles; to
  // rigid bodies when there is no RigidCallback either).
  bool fusable() const { return callbacks_.empty() && !coupled(); }
  // A 64-bit hash of every built-in term's kind and parameters (spring pairs included) and of
  // how many callbacks and coupled terms of the user's own the model holds (their code cannot
  // be hashed): what a checkpoint names the model it was taken under by.
  std::uint64_t fingerprint() const;

 private:
  std::vector<LocalTerm> local_;
  std::vector<ForceCallback<T>> callbacks_;
  std::vector<RigidCallback<T>> rigid_callbacks_;
  std::vector<std::shared_ptr<const CoupledTerm<T>>> coupled_;
  std::optional<NBody> nbody_;
  std::vector<SpringPair> springs_;
  std::vector<BodySpring> body_springs_;
};

// Throws kinema::Error naming `what`[k] and the field of the first bad pair in `pairs`
// (an index past kMaxSpringBodies, i == j, a parameter out of range, a pair repeated, a
// body with more than kMaxSpringsPerBody springs).
void check_springs(std::span<const SpringPair> pairs, const std::string& what);
// The same for body springs (a point not finite too).
void check_body_springs(std::span<const BodySpring> springs, const std::string& what);
// Throws kinema::Error naming `what` when G or the softening is not finite and >= 0.
void check_nbody(const NBody& term, const std::string& what);

// Name of a term as scenes spell it ("gravity", "linear_drag", ...).
std::string term_name(const LocalTerm& term);
// Whether the term acts on rigid bodies only (torques, angular drag, point forces, point
// springs): particles have no orientation, and their kernels leave it out.
bool acts_on_rigid_bodies_only(const LocalTerm& term);

extern template class ForceModel<float>;
extern template class ForceModel<double>;

}  // namespace kinema
