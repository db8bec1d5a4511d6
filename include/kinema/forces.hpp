#pragma once
// Force terms and the ForceModel that sums them.
//
// Local terms depend on one body's own state only; a model made of local terms alone is
// stepped by the fused single-pass kernels. Callback terms (user code over a block of
// bodies) and coupled terms (forces between bodies) switch the stepper to the staged path:
// one pass per stage, all bodies' stage state in memory.

#include <cstddef>
#include <functional>
#include <memory>
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
// a = -mu r / |r|^3 with r = x - center (mu: gravitational parameter G M).
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

using LocalTerm = std::variant<Gravity, LinearDrag, QuadraticDrag, Spring, Central, Torque,
                               AngularDrag, PointForce>;

// At most this many central attractors, and point forces, per model (they are evaluated
// in registers).
inline constexpr int kMaxCentralTerms = 4;
inline constexpr int kMaxPointForces = 4;

// What a callback or coupled term sees: the bodies [begin, begin + count) of one block at
// one stage, as SoA pointers already offset to `begin`. It adds forces into fx, fy, fz
// (zeroed before the call); they are divided by mass afterwards. Counts include the inert
// padding bodies at the end of the set (at the origin, inv_mass 0); forces on them are
// ignored.
template <class T>
struct ParticleBlock {
  std::size_t begin = 0;
  std::size_t count = 0;
  double t = 0;
  const T *px, *py, *pz, *vx, *vy, *vz, *inv_mass;
  T *fx, *fy, *fz;
};

// A user force over a block; must be safe to call concurrently for different blocks.
template <class T>
using ForceCallback = std::function<void(const ParticleBlock<T>&)>;

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
  ForceModel& add(std::shared_ptr<const CoupledTerm<T>> term);

  std::span<const LocalTerm> local_terms() const { return local_; }
  std::span<const ForceCallback<T>> callbacks() const { return callbacks_; }
  std::span<const std::shared_ptr<const CoupledTerm<T>>> coupled_terms() const { return coupled_; }
  // True when every term is local and built in: the fused path applies.
  bool fusable() const { return callbacks_.empty() && coupled_.empty(); }

 private:
  std::vector<LocalTerm> local_;
  std::vector<ForceCallback<T>> callbacks_;
  std::vector<std::shared_ptr<const CoupledTerm<T>>> coupled_;
};

// Name of a term as scenes spell it ("gravity", "linear_drag", ...).
std::string term_name(const LocalTerm& term);

extern template class ForceModel<float>;
extern template class ForceModel<double>;

}  // namespace kinema
