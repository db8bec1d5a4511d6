#include "kinema/bodies.hpp"

#include <algorithm>
#include <functional>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>
#include <string>
#include <utility>

#include "kinema/error.hpp"

namespace kinema {

template <class T>
AlignedArray<T>::AlignedArray(std::size_t count) {
  resize(count);
}

template <class T>
AlignedArray<T>::AlignedArray(const AlignedArray& other) {
  *this = other;
}

template <class T>
AlignedArray<T>& AlignedArray<T>::operator=(const AlignedArray& other) {
  if (this == &other) return *this;
  if (size_ < other.size_) {
    AlignedArray grown(other.size_);  // if this throws, *this is as it was
    *this = std::move(grown);
  }
  if (other.size_ > 0) std::memcpy(data_.get(), other.data_.get(), other.size_ * sizeof(T));
  std::fill(data_.get() + other.size_, data_.get() + size_, T(0));
  return *this;
}

template <class T>
void AlignedArray<T>::Free::operator()(T* p) const {
  ::operator delete[](p - shift, std::align_val_t{alignment});
}

namespace {

// Arrays of a page or more start at one of eight offsets within a page, 512 bytes apart,
// taken in turn: the arrays of a set, allocated together, then sit at distinct offsets, so
// that the kernels' many streams do not evict one another in the cache sets (faster than the
// offsets the heap happens to hand out: bench/README.md, "Measured while building the kernels").
constexpr std::size_t kPageBytes = 4096, kSlotBytes = 512;
std::atomic<std::size_t> next_slot{0};

struct Placement {
  std::size_t alignment, shift;  // shift in elements
};

template <class T>
Placement placement_for(std::size_t bytes) {
  if (bytes < kPageBytes) return {kSimdBytes, 0};
  const std::size_t slot = next_slot.fetch_add(1, std::memory_order_relaxed) % (kPageBytes / kSlotBytes);
  return {kPageBytes, slot * kSlotBytes / sizeof(T)};
}

}  // namespace

template <class T>
void AlignedArray<T>::check_count(std::size_t count) {
  if (count > (std::numeric_limits<std::size_t>::max() - 2 * kPageBytes) / sizeof(T)) {
    throw Error("cannot hold " + std::to_string(count) + " bodies: the arrays would overflow memory");
  }
}

template <class T>
void AlignedArray<T>::resize(std::size_t count) {
  check_count(count);
  count = padded_count<T>(count);
  if (count <= size_) return;
  const Placement at = placement_for<T>(count * sizeof(T));
  const Free free{at.alignment, at.shift};
  T* fresh = static_cast<T*>(::operator new[]((count + free.shift) * sizeof(T),
                                               std::align_val_t{free.alignment})) + free.shift;
  std::fill(fresh, fresh + count, T(0));
  if (size_ > 0) std::memcpy(fresh, data_.get(), size_ * sizeof(T));
  data_ = std::unique_ptr<T[], Free>(fresh, free);
  size_ = count;
}

namespace {

template <class T>
std::string number_text(T x) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", double(x));
  return text;
}

template <class T>
void check_finite(const Vec3<T>& v, std::size_t body, const char* field) {
  for (T c : v) {
    if (!std::isfinite(c)) {
      throw Error("body " + std::to_string(body) + ": " + field + " is not finite");
    }
  }
}

template <class T>
T inverse_mass(T mass, std::size_t i) {
  if (!(std::isfinite(mass) && mass > 0)) {
    throw Error("body " + std::to_string(i) + ": mass must be positive and finite, got " +
                number_text(mass));
  }
  const T inv_mass = T(1) / mass;
  if (!std::isfinite(inv_mass) || inv_mass == 0) {
    throw Error("body " + std::to_string(i) + ": mass " + number_text(mass) +
                " has no finite nonzero inverse in this precision");
  }
  return inv_mass;
}

// Grows a set's optional arrays (all or none) to at least `capacity` elements (one at least:
// an empty set's arrays exist too, once used), contents kept, new elements `fill`. New arrays
// first, moved in once all exist: a failed allocation changes nothing.
template <class T, std::size_t N>
void grow_all(std::array<AlignedArray<T>, N>& arrays, std::size_t capacity, const std::array<T, N>& fill) {
  capacity = std::max<std::size_t>(capacity, 1);
  const std::size_t kept = arrays[0].size();
  if (kept >= capacity) return;
  std::array<AlignedArray<T>, N> grown;
  for (std::size_t k = 0; k < N; ++k) {
    grown[k] = AlignedArray<T>(capacity);
    if (kept > 0) std::copy_n(arrays[k].data(), kept, grown[k].data());
    std::fill(grown[k].data() + kept, grown[k].data() + grown[k].size(), fill[k]);
  }
  arrays = std::move(grown);
}

}  // namespace

template <class T>
Vec3<T> AppliedVectors<T>::at(std::size_t i) const {
  if (!active_) return {};
  return {arrays_[0][i], arrays_[1][i], arrays_[2][i]};
}

template <class T>
void AppliedVectors<T>::check_add(std::size_t i, const Vec3<T>& v, const char* field) const {
  check_finite(v, i, field);
  const Vec3<T> old = at(i);
  const Vec3<T> sum{old[0] + v[0], old[1] + v[1], old[2] + v[2]};
  // The message is built only when it is needed: a game applies forces every frame.
  if (!(std::isfinite(sum[0]) && std::isfinite(sum[1]) && std::isfinite(sum[2]))) {
    check_finite(sum, i, (std::string(field) + " summed with the one already applied").c_str());
  }
}

template <class T>
void AppliedVectors<T>::add(std::size_t i, const Vec3<T>& v, std::size_t capacity, const char* field) {
  check_add(i, v, field);
  ensure(capacity);
  if (!active_) {
    for (auto& a : arrays_) std::fill(a.data(), a.data() + a.size(), T(0));
    active_ = true;
  }
  for (int d = 0; d < 3; ++d) arrays_[d][i] += v[d];
}

template <class T>
void AppliedVectors<T>::ensure(std::size_t capacity) {
  grow_all(arrays_, capacity, {});
}

template <class T>
void AppliedVectors<T>::grow(std::size_t capacity) {
  if (allocated()) ensure(capacity);  // never applied: stays without arrays
}

template <class T>
bool AppliedVectors<T>::fits(const AppliedVectors& other, std::size_t capacity) const {
  return !other.allocated() || (allocated() && arrays_[0].size() >= std::max(capacity, other.arrays_[0].size()));
}

template <class T>
void AppliedVectors<T>::assign(const AppliedVectors& other) {
  if (other.allocated()) {
    for (int d = 0; d < 3; ++d) arrays_[d] = other.arrays_[d];  // fits: copies, zeroes the rest
  }
  active_ = other.active_;
}

template <class T>
void AppliedVectors<T>::copy_body(std::size_t from, std::size_t to) {
  if (!allocated()) return;
  for (auto& a : arrays_) a[to] = a[from];
}

template <class T>
void AppliedVectors<T>::clear_body(std::size_t i) {
  if (!allocated()) return;
  for (auto& a : arrays_) a[i] = 0;
}

template <class T>
void BodyParameters<T>::set(BodyParameter k, std::size_t i, T value, std::size_t capacity) {
  ensure(capacity);
  if (!used(k)) {
    std::fill_n(arrays_[int(k)].data(), arrays_[int(k)].size(), default_of(k));
    largest_[int(k)] = std::abs(default_of(k));
  }
  used_[int(k)] = true;
  arrays_[int(k)][i] = value;
  largest_[int(k)] = std::max(largest_[int(k)], std::abs(value));
}

template <class T>
void BodyParameters<T>::ensure(std::size_t capacity) {
  grow_all(arrays_, capacity, {default_of(BodyParameter(0)), default_of(BodyParameter(1)), default_of(BodyParameter(2))});
}

template <class T>
void BodyParameters<T>::grow(std::size_t capacity) {
  if (allocated()) ensure(capacity);  // never set: stays without arrays
}

template <class T>
bool BodyParameters<T>::fits(const BodyParameters& other, std::size_t capacity) const {
  return !other.allocated() || (allocated() && arrays_[0].size() >= std::max(capacity, other.arrays_[0].size()));
}

template <class T>
void BodyParameters<T>::assign(const BodyParameters& other) {
  if (other.allocated()) {
    for (int k = 0; k < kKinds; ++k) {
      AlignedArray<T>& a = arrays_[k];
      std::copy_n(other.arrays_[k].data(), other.arrays_[k].size(), a.data());  // fits
      std::fill(a.data() + other.arrays_[k].size(), a.data() + a.size(), default_of(BodyParameter(k)));
    }
  }
  used_ = other.used_;
  largest_ = other.largest_;
}

template <class T>
void BodyParameters<T>::copy_body(std::size_t from, std::size_t to) {
  if (!allocated()) return;
  for (auto& a : arrays_) a[to] = a[from];
}

template <class T>
void BodyParameters<T>::clear_body(std::size_t i) {
  if (!allocated()) return;
  for (int k = 0; k < kKinds; ++k) arrays_[k][i] = default_of(BodyParameter(k));
}

// A factor may be any finite value (negative: the body falls up); a rate is not negative.
template <class T>
void ParticleSet<T>::set_parameter(BodyParameter k, std::size_t i, T value) {
  check_index(i);
  const bool factor = k == BodyParameter::gravity_factor;
  if (!std::isfinite(value) || (!factor && value < 0)) {
    const char* name = factor ? "gravity factor" : k == BodyParameter::linear_damping ? "linear damping" : "angular damping";
    throw Error("body " + std::to_string(i) + ": " + name + " must be " +
                (factor ? "finite" : "zero or positive and finite") + ", got " + number_text(value));
  }
  params_.set(k, i, value, capacity());
}

template <class T>
void ParticleSet<T>::apply_force(std::size_t i, const Vec3<T>& force) {
  check_index(i);
  applied_.add(i, force, capacity(), "force");
}

template <class T>
void ParticleSet<T>::apply_impulse(std::size_t i, const Vec3<T>& impulse) {
  check_index(i);
  check_finite(impulse, i, "impulse");
  const Vec3<T> v{vx_[i] + impulse[0] * inv_mass_[i], vy_[i] + impulse[1] * inv_mass_[i],
                  vz_[i] + impulse[2] * inv_mass_[i]};
  check_finite(v, i, "velocity after the impulse");
  vx_[i] = v[0], vy_[i] = v[1], vz_[i] = v[2];
}

template <class T>
void ParticleSet<T>::grow_to(std::size_t count) {
  // Geometric growth so adding one by one stays linear overall.
  std::size_t capacity = px_.size();
  if (count <= capacity) return;
  std::size_t target = std::max(count, capacity * 2);
  applied_.grow(target);  // first: arrays longer than the capacity are harmless, shorter not
  params_.grow(target);
  for (auto* a : {&px_, &py_, &pz_, &vx_, &vy_, &vz_, &inv_mass_}) a->resize(target);
}

template <class T>
void ParticleSet<T>::write(std::size_t i, const Vec3<T>& p, const Vec3<T>& v, T inv_mass) {
  px_[i] = p[0], py_[i] = p[1], pz_[i] = p[2];
  vx_[i] = v[0], vy_[i] = v[1], vz_[i] = v[2];
  inv_mass_[i] = inv_mass;
}

template <class T>
std::size_t ParticleSet<T>::add(const Vec3<T>& position, const Vec3<T>& velocity, T mass) {
  const std::size_t i = size_;
  check_finite(position, i, "position");
  check_finite(velocity, i, "velocity");
  const T inv_mass = inverse_mass(mass, i);
  grow_to(i + 1);
  write(i, position, velocity, inv_mass);
  size_ = i + 1;
  return i;
}

template <class T>
std::size_t ParticleSet<T>::add_kinematic(const Vec3<T>& position, const Vec3<T>& velocity) {
  const std::size_t i = size_;
  check_finite(position, i, "position");
  check_finite(velocity, i, "velocity");
  grow_to(i + 1);
  write(i, position, velocity, T(0));
  size_ = i + 1;
  return i;
}

// Every body checked before any is added: all or nothing.
template <class T>
void ParticleSet<T>::add(std::span<const ParticleDesc<T>> bodies) {
  for (std::size_t k = 0; k < bodies.size(); ++k) {
    check_finite(bodies[k].position, size_ + k, "position");
    check_finite(bodies[k].velocity, size_ + k, "velocity");
    inverse_mass(bodies[k].mass, size_ + k);
  }
  reserve(size_ + bodies.size());
  for (const auto& b : bodies) add(b);
}

template <class T>
ParticleSet<T>& ParticleSet<T>::operator=(const ParticleSet& other) {
  if (this == &other) return *this;
  if (!copy_fits(other)) return *this = ParticleSet(other);  // all or nothing
  applied_.assign(other.applied_);
  params_.assign(other.params_);
  keep_forces_ = other.keep_forces_;
  for (auto [to, from] : {std::pair{&px_, &other.px_}, {&py_, &other.py_}, {&pz_, &other.pz_}, {&vx_, &other.vx_},
                          {&vy_, &other.vy_}, {&vz_, &other.vz_}, {&inv_mass_, &other.inv_mass_}}) {
    *to = *from;  // fits: no allocation, no throw
  }
  size_ = other.size_;
  return *this;
}

template <class T>
ParticleSet<T>& ParticleSet<T>::operator=(ParticleSet&& other) noexcept {
  if (this == &other) return *this;
  px_ = std::move(other.px_), py_ = std::move(other.py_), pz_ = std::move(other.pz_);
  vx_ = std::move(other.vx_), vy_ = std::move(other.vy_), vz_ = std::move(other.vz_);
  inv_mass_ = std::move(other.inv_mass_);
  applied_ = std::move(other.applied_);
  params_ = std::move(other.params_);
  other.params_.clear();
  keep_forces_ = std::exchange(other.keep_forces_, false);
  size_ = std::exchange(other.size_, 0);
  return *this;
}

template <class T>
void ParticleSet<T>::reserve(std::size_t count) {
  applied_.grow(padded_count<T>(count));
  params_.grow(padded_count<T>(count));
  for (auto* a : {&px_, &py_, &pz_, &vx_, &vy_, &vz_, &inv_mass_}) a->resize(count);
}

template <class T>
void ParticleSet<T>::clear() {
  for (auto* a : {&px_, &py_, &pz_, &vx_, &vy_, &vz_, &inv_mass_}) {
    std::fill(a->data(), a->data() + a->size(), T(0));
  }
  applied_.clear();
  params_.clear();
  size_ = 0;
}

template <class T>
void ParticleSet<T>::check_index(std::size_t i) const {
  if (i >= size_) throw Error("body " + std::to_string(i) + ": no such body (the set has " + std::to_string(size_) + ")");
}

template <class T>
void ParticleSet<T>::set_position(std::size_t i, const Vec3<T>& p) {
  check_index(i);
  check_finite(p, i, "position");
  px_[i] = p[0], py_[i] = p[1], pz_[i] = p[2];
}

template <class T>
void ParticleSet<T>::set_velocity(std::size_t i, const Vec3<T>& v) {
  check_index(i);
  check_finite(v, i, "velocity");
  vx_[i] = v[0], vy_[i] = v[1], vz_[i] = v[2];
}

template <class T>
void ParticleSet<T>::set_mass(std::size_t i, T mass) {
  check_index(i);
  inv_mass_[i] = inverse_mass(mass, i);
}

template <class T>
void ParticleSet<T>::set_kinematic(std::size_t i) {
  check_index(i);
  inv_mass_[i] = 0;
}

template <class T>
void ParticleSet<T>::copy_body(std::size_t from, std::size_t to) {
  for (auto* a : {&px_, &py_, &pz_, &vx_, &vy_, &vz_, &inv_mass_}) (*a)[to] = (*a)[from];
  applied_.copy_body(from, to);
  params_.copy_body(from, to);
}

template <class T>
void ParticleSet<T>::clear_body(std::size_t i) {
  for (auto* a : {&px_, &py_, &pz_, &vx_, &vy_, &vz_, &inv_mass_}) (*a)[i] = 0;
  applied_.clear_body(i);
  params_.clear_body(i);
}

template <class T>
std::size_t ParticleSet<T>::remove(std::size_t i) {
  check_index(i);
  const std::size_t last = size_ - 1;
  if (i != last) copy_body(last, i);
  clear_body(last);  // inert padding again
  size_ = last;
  return i != last ? last : kNoBody;
}

void check_removals(std::span<const std::size_t> indices, std::size_t size, std::size_t* sorted) {
  std::copy(indices.begin(), indices.end(), sorted);
  std::sort(sorted, sorted + indices.size(), std::greater<>());
  for (std::size_t k = 0; k < indices.size(); ++k) {
    if (sorted[k] >= size) {
      throw Error("body " + std::to_string(sorted[k]) + ": no such body (the set has " + std::to_string(size) + ")");
    }
    if (k > 0 && sorted[k] == sorted[k - 1]) {
      throw Error("body " + std::to_string(sorted[k]) + ": listed twice for removal");
    }
  }
}

template class AlignedArray<float>;
template class AlignedArray<double>;
template class AppliedVectors<float>;
template class AppliedVectors<double>;
template class BodyParameters<float>;
template class BodyParameters<double>;
template class ParticleSet<float>;
template class ParticleSet<double>;

}  // namespace kinema
