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

namespace kinema {

template <class T>
using Vec3 = std::array<T, 3>;

// Storage alignment and padding unit, in bytes: one AVX-512 register.
inline constexpr std::size_t kSimdBytes = 64;

// A 64-byte aligned array of T whose capacity is always a multiple of 64 bytes.
template <class T>
class AlignedArray {
 public:
  AlignedArray() = default;
  explicit AlignedArray(std::size_t count);
  AlignedArray(const AlignedArray& other);
  AlignedArray& operator=(const AlignedArray& other);
  AlignedArray(AlignedArray&&) noexcept = default;
  AlignedArray& operator=(AlignedArray&&) noexcept = default;

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

  // Adds one body and returns its index. Throws kinema::Error on non-finite values or a
  // mass that is not positive and finite.
  std::size_t add(const Vec3<T>& position, const Vec3<T>& velocity, T mass);
  std::size_t add(const ParticleDesc<T>& desc) {
    return add(desc.position, desc.velocity, desc.mass);
  }
  // Adds a body that forces do not move (inv_mass 0); it keeps its velocity.
  std::size_t add_kinematic(const Vec3<T>& position, const Vec3<T>& velocity = {});
  // Adds many bodies at once (one growth of the buffers).
  void add(std::span<const ParticleDesc<T>> bodies);
  void reserve(std::size_t count);
  void clear();

  std::size_t size() const { return size_; }
  // Real bodies plus inert padding: the extent kernels run over.
  std::size_t padded_size() const { return padded_count<T>(size_); }

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
  void set_position(std::size_t i, const Vec3<T>& p);
  void set_velocity(std::size_t i, const Vec3<T>& v);

 private:
  void grow_to(std::size_t count);
  void write(std::size_t i, const Vec3<T>& p, const Vec3<T>& v, T inv_mass);

  AlignedArray<T> px_, py_, pz_, vx_, vy_, vz_, inv_mass_;
  std::size_t size_ = 0;
};

extern template class AlignedArray<float>;
extern template class AlignedArray<double>;
extern template class ParticleSet<float>;
extern template class ParticleSet<double>;

}  // namespace kinema
