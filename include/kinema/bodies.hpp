#pragma once
// Bodies as structure-of-arrays buffers.
//
// Every array is 64-byte aligned and padded to a multiple of 64 bytes (16 floats or
// 8 doubles) with inert bodies: zero position, zero velocity, inv_mass 0. Kernels
// therefore never need a scalar tail. A body with inv_mass 0 is kinematic: forces do not
// act on it and it keeps its velocity (zero velocity makes it static).

#include <array>
#include <cstddef>
#include <memory>
#include <span>
#include <utility>

namespace kinema {

template <class T>
using Vec3 = std::array<T, 3>;

template <class T>
class RigidBodySet;

namespace detail {
struct CheckpointCodec;  // reads and writes the sets' arrays as they are (kinema/checkpoint.hpp)
struct StateSwap;  // trades a set's state arrays with the finiteness guard's buffer (src/step)
}

// Storage alignment and padding unit, in bytes: one AVX-512 register.
inline constexpr std::size_t kSimdBytes = 64;

// A 64-byte aligned array of T whose capacity is always a multiple of 64 bytes.
template <class T>
class AlignedArray {
 public:
  AlignedArray() = default;
  explicit AlignedArray(std::size_t count);
  AlignedArray(const AlignedArray& other);
  // Reuses this array's memory when it is large enough (the rest is zeroed): copying a set
  // into one of the same capacity allocates nothing.
  AlignedArray& operator=(const AlignedArray& other);
  // A moved-from array is empty.
  AlignedArray(AlignedArray&& other) noexcept
      : data_(std::move(other.data_)), size_(std::exchange(other.size_, 0)) {}
  AlignedArray& operator=(AlignedArray&& other) noexcept {
    if (this != &other) data_ = std::move(other.data_), size_ = std::exchange(other.size_, 0);
    return *this;
  }

  // Throws kinema::Error when `count` elements would overflow memory, as resize does.
  static void check_count(std::size_t count);

  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  std::size_t size() const { return size_; }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  std::span<T> span() { return {data(), size_}; }
  std::span<const T> span() const { return {data(), size_}; }

  // Grows to at least `count` elements, keeping the contents; new elements are zero.
  void resize(std::size_t count);

 private:
  struct Free {
    std::size_t alignment = kSimdBytes;
    std::size_t shift = 0;  // elements between the allocation and data()
    void operator()(T* p) const;
  };
  std::unique_ptr<T[], Free> data_;
  std::size_t size_ = 0;
};

// Number of T that fill whole 64-byte lines for `count` elements.
template <class T>
constexpr std::size_t padded_count(std::size_t count) {
  constexpr std::size_t lane = kSimdBytes / sizeof(T);
  return (count + lane - 1) / lane * lane;
}

// Vectors applied to single bodies from outside the force model (the game's forces and
// torques): three component arrays, none or all at least as long as the set's capacity (so
// kernels may read them to padded_size()). A set allocates them at its first apply and never
// before: a set that applies nothing carries and reads no such arrays. clear() only marks
// them unused (no pass over memory); the next add zeroes them first. Every change that
// allocates does so before anything changes.
template <class T>
class AppliedVectors {
 public:
  AppliedVectors() = default;
  AppliedVectors(const AppliedVectors&) = default;  // the source's lengths: its set's capacity
  AppliedVectors& operator=(const AppliedVectors&) = delete;  // see fits and assign
  // A moved-from value holds nothing.
  AppliedVectors(AppliedVectors&& other) noexcept
      : arrays_(std::move(other.arrays_)), active_(std::exchange(other.active_, false)) {}
  AppliedVectors& operator=(AppliedVectors&& other) noexcept {
    arrays_ = std::move(other.arrays_), active_ = std::exchange(other.active_, false);
    return *this;
  }

  bool active() const { return active_; }
  // Component d's array while active, else nullptr (what the kernels test).
  const T* data(int d) const { return active_ ? arrays_[d].data() : nullptr; }
  Vec3<T> at(std::size_t i) const;  // zero when not active
  // Throws the kinema::Error add(i, v, ...) would throw (v or the sum not finite, naming the
  // body and `field`), changing nothing.
  void check_add(std::size_t i, const Vec3<T>& v, const char* field) const;
  // Adds v to body i, whose set has `capacity` elements per array (checked as check_add).
  void add(std::size_t i, const Vec3<T>& v, std::size_t capacity, const char* field);
  void clear() { active_ = false; }
  void grow(std::size_t capacity);  // keeps arrays, if any, as long as the set's
  // Whether assign(other) needs no allocation for a set of `capacity`.
  bool fits(const AppliedVectors& other, std::size_t capacity) const;
  void assign(const AppliedVectors& other);  // only where fits: allocates nothing
  void copy_body(std::size_t from, std::size_t to);
  void clear_body(std::size_t i);

 private:
  friend struct detail::CheckpointCodec;
  bool allocated() const { return arrays_[0].size() > 0; }
  void ensure(std::size_t capacity);  // all three at least `capacity` long, contents kept

  std::array<AlignedArray<T>, 3> arrays_;
  bool active_ = false;
};

// Parameters engines keep per body: a gravity factor (the body feels factor times every
// Gravity term; default 1), a linear damping rate c (an extra acceleration -c v, per second,
// whatever the mass; default 0) and, for rigid bodies, an angular damping rate c (an extra
// torque -c L, so omega decays as exp(-c t) about a principal axis; default 0). A set
// allocates the three arrays at its first set_... call and never before; kernels read only
// the kinds that were set. Every change that allocates does so before anything changes.
enum class BodyParameter { gravity_factor, linear_damping, angular_damping };

template <class T>
class BodyParameters {
 public:
  static constexpr int kKinds = 3;
  static constexpr T default_of(BodyParameter k) { return k == BodyParameter::gravity_factor ? T(1) : T(0); }

  bool any() const { return used_[0] || used_[1] || used_[2]; }
  bool used(BodyParameter k) const { return used_[int(k)]; }
  T at(BodyParameter k, std::size_t i) const { return used(k) ? arrays_[int(k)][i] : default_of(k); }
  // The largest magnitude set since the kind was last cleared (what overflow checks use).
  T largest(BodyParameter k) const { return used(k) ? largest_[int(k)] : default_of(k); }
  // The kind's array (the set's capacity long) once set, else nullptr (what the kernels test).
  const T* data(BodyParameter k) const { return used(k) ? arrays_[int(k)].data() : nullptr; }
  // Sets body i's value, allocating the arrays (for `capacity` bodies) at the first call.
  void set(BodyParameter k, std::size_t i, T value, std::size_t capacity);
  void grow(std::size_t capacity);  // keeps arrays, if any, as long as the set's
  bool fits(const BodyParameters& other, std::size_t capacity) const;
  void assign(const BodyParameters& other);  // only where fits: allocates nothing
  void copy_body(std::size_t from, std::size_t to);
  void clear_body(std::size_t i);  // the defaults
  void clear() { used_ = {}, largest_ = {}; }

 private:
  friend struct detail::CheckpointCodec;
  bool allocated() const { return arrays_[0].size() > 0; }
  // All at least `capacity` long (one SIMD width at least), new elements the defaults.
  void ensure(std::size_t capacity);

  std::array<AlignedArray<T>, kKinds> arrays_;
  std::array<bool, kKinds> used_{};
  std::array<T, kKinds> largest_{};
};

template <class T>
struct ParticleDesc {
  Vec3<T> position{};
  Vec3<T> velocity{};
  T mass = 1;  // > 0 and finite; use inverse_mass 0 through add_kinematic for immovable bodies
};

template <class T>
class ParticleSet {
 public:
  ParticleSet() = default;
  ParticleSet(const ParticleSet&) = default;
  // Reuses this set's arrays when they are large enough (no allocation); else copies into new
  // ones first, so a failed allocation leaves this set as it was.
  ParticleSet& operator=(const ParticleSet& other);
  // A moved-from set is empty and usable.
  ParticleSet(ParticleSet&& other) noexcept { *this = std::move(other); }
  ParticleSet& operator=(ParticleSet&& other) noexcept;

  // Adds one body and returns its index. Throws kinema::Error on non-finite values or a
  // mass that is not positive and finite.
  std::size_t add(const Vec3<T>& position, const Vec3<T>& velocity, T mass);
  std::size_t add(const ParticleDesc<T>& desc) {
    return add(desc.position, desc.velocity, desc.mass);
  }
  // Adds a body that forces do not move (inv_mass 0); it keeps its velocity.
  std::size_t add_kinematic(const Vec3<T>& position, const Vec3<T>& velocity = {});
  // Adds many bodies at once (one growth of the buffers), all or none: a body refused (as
  // add refuses it, named by the index it would have had) leaves the set as it was.
  void add(std::span<const ParticleDesc<T>> bodies);
  void reserve(std::size_t count);
  void clear();

  std::size_t size() const { return size_; }
  // Real bodies plus inert padding: the extent kernels run over.
  std::size_t padded_size() const { return padded_count<T>(size_); }
  // Elements allocated per array (grows geometrically as bodies are added).
  std::size_t capacity() const { return px_.size(); }

  // The SoA arrays, each of padded_size() elements.
  T* px() { return px_.data(); }
  T* py() { return py_.data(); }
  T* pz() { return pz_.data(); }
  T* vx() { return vx_.data(); }
  T* vy() { return vy_.data(); }
  T* vz() { return vz_.data(); }
  const T* px() const { return px_.data(); }
  const T* py() const { return py_.data(); }
  const T* pz() const { return pz_.data(); }
  const T* vx() const { return vx_.data(); }
  const T* vy() const { return vy_.data(); }
  const T* vz() const { return vz_.data(); }
  const T* inv_mass() const { return inv_mass_.data(); }

  Vec3<T> position(std::size_t i) const { return {px_[i], py_[i], pz_[i]}; }
  Vec3<T> velocity(std::size_t i) const { return {vx_[i], vy_[i], vz_[i]}; }
  // Setters check the index and the values (kinema::Error naming the body and field).
  void set_position(std::size_t i, const Vec3<T>& p);
  void set_velocity(std::size_t i, const Vec3<T>& v);
  void set_mass(std::size_t i, T mass);  // positive and finite; makes a kinematic body dynamic
  void set_kinematic(std::size_t i);     // forces stop moving it (inv_mass 0)

  // Forces from the game, per body. An applied force acts, constant, over every step of the
  // next Stepper::step or advance (or advance_to) call that takes a step, as part of the
  // body's acceleration (F inv_mass), and is cleared when that call returns, unless
  // keep_forces(true) keeps it for later calls too. A call that throws, or takes no step,
  // leaves the forces applied. Forces on one body
  // add up. Bodies with inv_mass 0 (kinematic) ignore them. The first apply allocates the
  // set's force arrays; a set that never applies a force carries none, and its steps cost
  // what they cost without this feature. kinema::Error for a bad index or a non-finite value.
  void apply_force(std::size_t i, const Vec3<T>& force);
  // An immediate change of momentum: v += J inv_mass (nothing for a kinematic body).
  void apply_impulse(std::size_t i, const Vec3<T>& impulse);
  void clear_forces() { applied_.clear(); }
  void keep_forces(bool keep) { keep_forces_ = keep; }
  bool keeps_forces() const { return keep_forces_; }
  bool has_applied_forces() const { return applied_.active(); }
  // Body i's applied force (zero when none); kinema::Error for a bad index.
  Vec3<T> applied_force(std::size_t i) const {
    check_index(i);
    return applied_.at(i);
  }
  // Component d (0..2: x, y, z) of the applied forces, padded_size() long; nullptr when none.
  const T* applied_force_data(int d) const { return applied_.data(d); }

  // Per-body parameters (see BodyParameters): they stay until set again. kinema::Error for
  // a bad index, a factor that is not finite or a rate that is negative or not finite.
  void set_gravity_factor(std::size_t i, T factor) { set_parameter(BodyParameter::gravity_factor, i, factor); }
  void set_linear_damping(std::size_t i, T rate) { set_parameter(BodyParameter::linear_damping, i, rate); }
  T gravity_factor(std::size_t i) const { return parameter(BodyParameter::gravity_factor, i); }
  T linear_damping(std::size_t i) const { return parameter(BodyParameter::linear_damping, i); }
  const BodyParameters<T>& parameters() const { return params_; }

  // Removes body i by moving the last body into its place (no reallocation, no shift).
  // Returns the index the moved body had (the old last index), or kNoBody when i was last.
  static constexpr std::size_t kNoBody = std::size_t(-1);
  std::size_t remove(std::size_t i);
  // Removes every listed body (distinct indices, any order), each by swap with the last,
  // from the highest index down; moved(from, to) is told of each move in the order they
  // happen, with indices as they are at that moment (a body may move twice: follow the
  // reports in order, as a handle table does).
  template <class Moved>
  void remove(std::span<const std::size_t> indices, Moved&& moved);

 private:
  friend class RigidBodySet<T>;
  friend struct detail::CheckpointCodec;
  friend struct detail::StateSwap;
  void check_index(std::size_t i) const;
  T parameter(BodyParameter k, std::size_t i) const {
    check_index(i);
    return params_.at(k, i);
  }
  void set_parameter(BodyParameter k, std::size_t i, T value);
  // Whether copying `other` in place needs no allocation.
  bool copy_fits(const ParticleSet& other) const {
    return capacity() >= other.capacity() && applied_.fits(other.applied_, capacity()) &&
           params_.fits(other.params_, capacity());
  }
  // Copies body `from` to `to` in every array, or clears `to` to inert padding.
  void copy_body(std::size_t from, std::size_t to);
  void clear_body(std::size_t i);

  void grow_to(std::size_t count);
  void write(std::size_t i, const Vec3<T>& p, const Vec3<T>& v, T inv_mass);

  AlignedArray<T> px_, py_, pz_, vx_, vy_, vz_, inv_mass_;
  std::size_t size_ = 0;
  AppliedVectors<T> applied_;
  bool keep_forces_ = false;
  BodyParameters<T> params_;
};

template <class T>
using Quat = std::array<T, 4>;  // (w, x, y, z), rotating body-frame vectors into the world

// A rigid body as given by a user. Orientation need not be normalized (it is on add).
// The body frame is the principal frame: `inertia` holds the principal moments. Use
// `principal_frame` to turn a full inertia tensor into this form.
template <class T>
struct RigidBodyDesc {
  Vec3<T> position{};
  Vec3<T> velocity{};
  Quat<T> orientation{1, 0, 0, 0};
  Vec3<T> angular_momentum{};  // world frame
  T mass = 1;
  Vec3<T> inertia{1, 1, 1};   // principal moments, body frame
};

// Rigid bodies: the particle arrays for the centre of mass, plus orientation quaternion
// (qw qx qy qz), world angular momentum (lx ly lz) and inverse principal moments of
// inertia (inv_ix inv_iy inv_iz). Padding bodies have identity orientation and zero
// everything else, so they stay inert.
template <class T>
class RigidBodySet {
 public:
  // Throws kinema::Error naming the body and field on non-finite values, a mass or moment
  // that is not positive and finite, or a zero orientation quaternion. (Moments that break
  // the triangle inequality I1 + I2 >= I3 describe no solid body but are accepted: textbook
  // examples use them.)
  std::size_t add(const RigidBodyDesc<T>& body);
  void reserve(std::size_t count);
  RigidBodySet() = default;
  RigidBodySet(const RigidBodySet&) = default;
  // Reuses this set's memory when it is large enough: no allocation for a snapshot; else
  // copies into new arrays first (a failed allocation leaves this set as it was).
  RigidBodySet& operator=(const RigidBodySet& other);
  RigidBodySet(RigidBodySet&&) noexcept = default;
  RigidBodySet& operator=(RigidBodySet&&) noexcept = default;

  // Setters, checked as add() checks (kinema::Error naming the body and field).
  void set_position(std::size_t i, const Vec3<T>& p) { centers_.set_position(i, p); }
  void set_velocity(std::size_t i, const Vec3<T>& v) { centers_.set_velocity(i, v); }
  void set_orientation(std::size_t i, const Quat<T>& q);  // normalized here
  void set_angular_momentum(std::size_t i, const Vec3<T>& l);
  void set_mass(std::size_t i, T mass);
  void set_inertia(std::size_t i, const Vec3<T>& principal_moments);
  // Forces and torques stop moving it: inv_mass and inverse moments 0. It keeps its velocity
  // and does not turn. set_mass makes its centre dynamic again and set_inertia its rotation
  // (torques meanwhile still change L, which then turns it).
  void set_kinematic(std::size_t i);
  // Forces from the game, as ParticleSet's (the same life: the next call, or kept), plus
  // torques. apply_force pushes the centre of mass; apply_force_at(i, F, p), p a world point,
  // also gives the torque (p - x) x F about the centre x as it is now; apply_torque adds a
  // world torque. Impulses change velocity (J inv_mass) and world angular momentum (the
  // angular impulse, or (p - x) x J at a point) at once. Bodies with inv_mass 0 ignore all.
  void apply_force(std::size_t i, const Vec3<T>& force) { centers_.apply_force(i, force); }
  void apply_force_at(std::size_t i, const Vec3<T>& force, const Vec3<T>& world_point);
  void apply_torque(std::size_t i, const Vec3<T>& torque);
  void apply_impulse(std::size_t i, const Vec3<T>& impulse) { centers_.apply_impulse(i, impulse); }
  void apply_impulse_at(std::size_t i, const Vec3<T>& impulse, const Vec3<T>& world_point);
  void apply_angular_impulse(std::size_t i, const Vec3<T>& impulse);
  void clear_forces() { centers_.clear_forces(), torques_.clear(); }
  void keep_forces(bool keep) { centers_.keep_forces(keep); }
  bool keeps_forces() const { return centers_.keeps_forces(); }
  bool has_applied_forces() const { return centers_.has_applied_forces() || torques_.active(); }
  Vec3<T> applied_force(std::size_t i) const { return centers_.applied_force(i); }
  Vec3<T> applied_torque(std::size_t i) const {
    centers_.check_index(i);
    return torques_.at(i);
  }
  const T* applied_torque_data(int d) const { return torques_.data(d); }  // nullptr when none
  // Per-body parameters, as ParticleSet's, plus angular damping (the torque -c L).
  void set_gravity_factor(std::size_t i, T factor) { centers_.set_gravity_factor(i, factor); }
  void set_linear_damping(std::size_t i, T rate) { centers_.set_linear_damping(i, rate); }
  void set_angular_damping(std::size_t i, T rate) { centers_.set_parameter(BodyParameter::angular_damping, i, rate); }
  T gravity_factor(std::size_t i) const { return centers_.gravity_factor(i); }
  T linear_damping(std::size_t i) const { return centers_.linear_damping(i); }
  T angular_damping(std::size_t i) const { return centers_.parameter(BodyParameter::angular_damping, i); }
  const BodyParameters<T>& parameters() const { return centers_.params_; }

  // As ParticleSet::remove: the last body moves into i; returns its old index or kNoBody.
  static constexpr std::size_t kNoBody = ParticleSet<T>::kNoBody;
  std::size_t remove(std::size_t i);
  template <class Moved>
  void remove(std::span<const std::size_t> indices, Moved&& moved);

  std::size_t size() const { return centers_.size(); }
  std::size_t padded_size() const { return centers_.padded_size(); }

  // The centre-of-mass arrays, as a ParticleSet (px ... vz, inv_mass). Read-only: bodies
  // come through add(), which keeps the rotation arrays as long as these.
  const ParticleSet<T>& centers() const { return centers_; }
  // The centre arrays for bulk writes (d = 0..2: x, y, z), as q() and l() are; unchecked.
  T* position_data(int d) { return d == 0 ? centers_.px() : d == 1 ? centers_.py() : centers_.pz(); }
  T* velocity_data(int d) { return d == 0 ? centers_.vx() : d == 1 ? centers_.vy() : centers_.vz(); }
  T* q(int k) { return q_[k].data(); }  // k = 0..3: w, x, y, z
  const T* q(int k) const { return q_[k].data(); }
  T* l(int d) { return l_[d].data(); }  // world angular momentum
  const T* l(int d) const { return l_[d].data(); }
  const T* inv_inertia(int d) const { return inv_inertia_[d].data(); }

  Quat<T> orientation(std::size_t i) const { return {q_[0][i], q_[1][i], q_[2][i], q_[3][i]}; }
  Vec3<T> angular_momentum(std::size_t i) const { return {l_[0][i], l_[1][i], l_[2][i]}; }
  // World angular velocity omega = R diag(1/I) R^T L, computed in double.
  Vec3<double> angular_velocity(std::size_t i) const;

 private:
  friend struct detail::CheckpointCodec;
  void grow_rotation_arrays();
  void pad_rotation_arrays(std::size_t from);  // identity orientation from `from` on
  // (p - x_i) x v in double, checked finite in T.
  Vec3<T> moment_about(std::size_t i, const Vec3<T>& v, const Vec3<T>& world_point, const char* field) const;

  ParticleSet<T> centers_;
  std::array<AlignedArray<T>, 4> q_;
  std::array<AlignedArray<T>, 3> l_, inv_inertia_;
  AppliedVectors<T> torques_;
};

// Principal moments of a symmetric inertia tensor (body frame) and the rotation from the
// principal frame to that body frame, for RigidBodyDesc: orientation_world * rotation gives
// the orientation of the principal frame. Throws kinema::Error when the tensor is not
// symmetric, not finite or not positive definite.
struct PrincipalFrame {
  Vec3<double> moments;
  Quat<double> rotation;
};
PrincipalFrame principal_frame(const std::array<std::array<double, 3>, 3>& inertia);

// Quaternion product a * b.
template <class T>
Quat<T> multiply(const Quat<T>& a, const Quat<T>& b) {
  return {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
          a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
          a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
          a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
}

// v rotated by the unit quaternion q.
Vec3<double> rotate(const Quat<double>& q, const Vec3<double>& v);

// Both sets remove a batch the same way: highest index first, each by swap with the last.
template <class Set, class Moved>
void remove_bodies(Set& set, std::span<const std::size_t> indices, Moved&& moved);

template <class T>
template <class Moved>
void ParticleSet<T>::remove(std::span<const std::size_t> indices, Moved&& moved) {
  remove_bodies(*this, indices, moved);
}

template <class T>
template <class Moved>
void RigidBodySet<T>::remove(std::span<const std::size_t> indices, Moved&& moved) {
  remove_bodies(*this, indices, moved);
}

// Throws kinema::Error for an index out of range or listed twice.
void check_removals(std::span<const std::size_t> indices, std::size_t size, std::size_t* sorted);

template <class Set, class Moved>
void remove_bodies(Set& set, std::span<const std::size_t> indices, Moved&& moved) {
  constexpr std::size_t kOnStack = 256;
  std::size_t stack[kOnStack];
  std::unique_ptr<std::size_t[]> heap;
  std::size_t* sorted = indices.size() <= kOnStack ? stack : (heap.reset(new std::size_t[indices.size()]), heap.get());
  check_removals(indices, set.size(), sorted);  // sorted descending
  for (std::size_t k = 0; k < indices.size(); ++k) {
    const std::size_t from = set.remove(sorted[k]);
    if (from != Set::kNoBody) moved(from, sorted[k]);
  }
}

extern template class AlignedArray<float>;
extern template class AppliedVectors<float>;
extern template class AppliedVectors<double>;
extern template class BodyParameters<float>;
extern template class BodyParameters<double>;
extern template class AlignedArray<double>;
extern template class ParticleSet<float>;
extern template class ParticleSet<double>;
extern template class RigidBodySet<float>;
extern template class RigidBodySet<double>;

}  // namespace kinema
