#include "step/finite_guard.hpp"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>

#include "kernels/reductions.hpp"
#include "parallel/blocks.hpp"

namespace kinema {
namespace {

// One key per (body, field), ordered as errors report them: by body, then field.
constexpr std::size_t kNoKey = std::numeric_limits<std::size_t>::max();

std::size_t key(std::size_t body, int field) { return body * StateArrays<float>::kMax + std::size_t(field); }

void keep_lowest(std::atomic<std::size_t>& lowest, std::size_t k) {
  std::size_t seen = lowest.load(std::memory_order_relaxed);
  while (k < seen && !lowest.compare_exchange_weak(seen, k, std::memory_order_relaxed)) {
  }
}

// The first index in [begin, end) whose value is not finite, or end.
template <class T>
std::size_t first_bad(const T* a, std::size_t begin, std::size_t end) {
  if (!any_not_finite(a + begin, end - begin)) return end;
  for (std::size_t i = begin; i < end; ++i) {
    if (!std::isfinite(a[i])) return i;
  }
  return end;
}

// Bodies in [begin, end) whose |(x, y, z)| may exceed `limit` (NaN aside; a square that
// overflows counts), in a loop that vectorizes, so that blocks within the limit skip the
// exact clamp. The test in T errs on the side of counting: it compares with 0.999 limit^2.
template <class T>
int count_over(const T* x, const T* y, const T* z, std::nullptr_t, T limit, std::size_t begin, std::size_t end) {
  const T limit2 = T(0.999) * limit * limit;
  int over = 0;
  for (std::size_t i = begin; i < end; ++i) over += x[i] * x[i] + y[i] * y[i] + z[i] * z[i] > limit2;
  return over;
}

// The same for angular speed, by the bound |omega| <= |L| max(1 / I).
template <class T>
int count_over_angular(const T* lx, const T* ly, const T* lz, const T* ix, const T* iy, const T* iz, T limit,
                       std::size_t begin, std::size_t end) {
  const T limit2 = T(0.999) * limit * limit;
  int over = 0;
  for (std::size_t i = begin; i < end; ++i) {
    const T inv = std::max(ix[i], std::max(iy[i], iz[i]));
    over += (lx[i] * lx[i] + ly[i] * ly[i] + lz[i] * lz[i]) * (inv * inv) > limit2;
  }
  return over;
}

// The length of (x, y, z) without overflow; infinite components make it +inf.
double length(double x, double y, double z) {
  const double m = std::max({std::abs(x), std::abs(y), std::abs(z)});
  if (!(m > 0) || std::isinf(m)) return m;
  return m * std::sqrt((x / m) * (x / m) + (y / m) * (y / m) + (z / m) * (z / m));
}

// v scaled down to length `limit` when longer. An infinite vector keeps the direction of
// its infinite components; a vector holding NaN is left for the scan to find.
template <class T>
void clamp(T& x, T& y, T& z, double limit) {
  double v[3] = {double(x), double(y), double(z)};
  if (std::isnan(v[0]) || std::isnan(v[1]) || std::isnan(v[2])) return;
  const double n = length(v[0], v[1], v[2]);
  if (!(n > limit)) return;
  if (std::isinf(n)) {
    for (double& c : v) c = std::isinf(c) ? std::copysign(1.0, c) : 0.0;
  }
  const double scale = limit / length(v[0], v[1], v[2]);
  x = T(v[0] * scale), y = T(v[1] * scale), z = T(v[2] * scale);
}

// Body i's angular momentum scaled so that its angular velocity is at most `limit`.
template <class T>
void clamp_angular(RigidBodySet<T>& b, std::size_t i, double limit) {
  T *lx = b.l(0), *ly = b.l(1), *lz = b.l(2);
  // omega is linear in L: first give an infinite L a direction, then scale it.
  clamp(lx[i], ly[i], lz[i], double(std::numeric_limits<T>::max()));
  const Vec3<double> w = b.angular_velocity(i);
  const double speed = length(w[0], w[1], w[2]);
  if (speed > limit) {
    const double scale = limit / speed;
    lx[i] = T(lx[i] * scale), ly[i] = T(ly[i] * scale), lz[i] = T(lz[i] * scale);
  }
}

}  // namespace

template <class T>
StateArrays<T> state_arrays(ParticleSet<T>& b) {
  StateArrays<T> s{b.size(), b.padded_size(), 6, {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()},
                   {"px", "py", "pz", "vx", "vy", "vz"}};
  return s;
}

template <class T>
StateArrays<T> state_arrays(RigidBodySet<T>& b) {
  return {b.size(), b.padded_size(), 13,
          {b.position_data(0), b.position_data(1), b.position_data(2), b.velocity_data(0),
           b.velocity_data(1), b.velocity_data(2), b.q(0), b.q(1), b.q(2), b.q(3), b.l(0), b.l(1),
           b.l(2)},
          {"px", "py", "pz", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "lx", "ly", "lz"}};
}

template <class T>
void Checkpoint<T>::reserve(const StateArrays<T>& s) {
  for (int a = 0; a < s.count; ++a) {
    if (copy_[a].size() < s.padded) copy_[a] = AlignedArray<T>(s.padded);
  }
  if (saved_in_.size() < block_count(s.padded)) saved_in_.resize(block_count(s.padded));
  ++call_;
}

template <class T>
void Checkpoint<T>::save(const StateArrays<T>& s, Block b) {
  for (int a = 0; a < s.count; ++a) {
    std::memcpy(copy_[a].data() + b.begin, s.data[a] + b.begin, (b.end - b.begin) * sizeof(T));
  }
  saved_in_[b.begin / kBlockBodies] = call_;
}

template <class T>
void Checkpoint<T>::restore(const Workers& workers, const StateArrays<T>& s) const {
  const auto put_back = [&](Block b) {
    if (saved_in_[b.begin / kBlockBodies] != call_) return;
    for (int a = 0; a < s.count; ++a) {
      std::memcpy(s.data[a] + b.begin, copy_[a].data() + b.begin, (b.end - b.begin) * sizeof(T));
    }
  };
  try {
    for_each_block(workers, s.padded, put_back);
  } catch (...) {
    for_each_block(Workers{}, s.padded, put_back);  // a host's enqueue threw: nothing ran
  }
}

template <class T>
std::size_t Checkpoint<T>::bytes() const {
  std::size_t n = 0;
  for (const auto& a : copy_) n += a.size() * sizeof(T);
  return n;
}

template <class T>
void FiniteScan<T>::scan(Block b) {
  const std::size_t end = std::min(b.end, state_.size);  // padding is always finite
  if (b.begin >= end || !any_not_finite(state_.data.data(), state_.count, b.begin, end)) return;
  for (int a = 0; a < state_.count; ++a) {
    const std::size_t i = first_bad(state_.data[a], b.begin, end);
    if (i < end) keep_lowest(lowest_, key(i, a));
  }
}

template <class T>
std::optional<NonFinite> FiniteScan<T>::found() const {
  const std::size_t k = lowest_.load();
  if (k == kNoKey) return std::nullopt;
  return NonFinite{k / StateArrays<T>::kMax, state_.names[k % StateArrays<T>::kMax]};
}

template <class T>
void clamp_speeds(T* const velocity[3], const T* inv_mass, std::size_t size, Block block, double max_speed) {
  T *vx = velocity[0], *vy = velocity[1], *vz = velocity[2];
  const std::size_t end = std::min(block.end, size);
  if (count_over<T>(vx, vy, vz, nullptr, T(max_speed), block.begin, end) == 0) return;
  for (std::size_t i = block.begin; i < end; ++i) {
    if (inv_mass[i] != 0) clamp(vx[i], vy[i], vz[i], max_speed);
  }
}

template <class T>
void clamp_speeds(ParticleSet<T>& b, Block block, double max_speed) {
  T* const velocity[3] = {b.vx(), b.vy(), b.vz()};
  clamp_speeds(velocity, b.inv_mass(), b.size(), block, max_speed);
}

}  // namespace kinema

namespace kinema::detail {

struct StateSwap {
  template <class T>
  static std::array<AlignedArray<T>*, 6> state(ParticleSet<T>& s) {
    return {&s.px_, &s.py_, &s.pz_, &s.vx_, &s.vy_, &s.vz_};
  }
};

}  // namespace kinema::detail

namespace kinema {

template <class T>
void StateBuffer<T>::reserve(const ParticleSet<T>& set) {
  if (copy_[0].size() == set.capacity()) return;
  // All six or none: arrays of two lengths would become a set's.
  std::array<AlignedArray<T>, 6> grown;
  for (auto& a : grown) a = AlignedArray<T>(set.capacity());
  copy_ = std::move(grown);
  written_end_ = 0;
}

template <class T>
StateArrays<T> StateBuffer<T>::arrays(const ParticleSet<T>& set) {
  // Whatever the call writes (up to the padded size) counts, even when the call then fails.
  written_end_ = std::max(written_end_, set.padded_size());
  StateArrays<T> s = state_arrays(const_cast<ParticleSet<T>&>(set));
  for (int a = 0; a < 6; ++a) s.data[a] = copy_[a].data();
  return s;
}

template <class T>
void StateBuffer<T>::swap_into(ParticleSet<T>& set) {
  const std::size_t padded = set.padded_size();
  if (written_end_ > padded) {
    for (auto& a : copy_) std::fill(a.data() + padded, a.data() + written_end_, T(0));
  }
  const auto state = detail::StateSwap::state(set);
  for (int a = 0; a < 6; ++a) std::swap(*state[a], copy_[a]);
  written_end_ = padded;  // the set's old arrays: its state to there, zero past it
}

template <class T>
std::size_t StateBuffer<T>::bytes() const {
  return copy_.size() * copy_[0].size() * sizeof(T);
}

template <class T>
void clamp_speeds(RigidBodySet<T>& b, Block block, double max_speed, double max_angular_speed) {
  T *vx = b.velocity_data(0), *vy = b.velocity_data(1), *vz = b.velocity_data(2);
  const T *lx = b.l(0), *ly = b.l(1), *lz = b.l(2);
  const T* inv_mass = b.centers().inv_mass();
  const T *ix = b.inv_inertia(0), *iy = b.inv_inertia(1), *iz = b.inv_inertia(2);
  const std::size_t end = std::min(block.end, b.size());
  if (count_over<T>(vx, vy, vz, nullptr, T(max_speed), block.begin, end) > 0) {
    for (std::size_t i = block.begin; i < end; ++i) {
      if (inv_mass[i] != 0) clamp(vx[i], vy[i], vz[i], max_speed);
    }
  }
  // |omega| <= |L| max(1 / I): bodies under the limit by that bound are left alone.
  if (count_over_angular(lx, ly, lz, ix, iy, iz, T(max_angular_speed), block.begin, end) == 0) return;
  for (std::size_t i = block.begin; i < end; ++i) clamp_angular(b, i, max_angular_speed);
}

#define KINEMA_GUARD(T)                                                                        \
  template StateArrays<T> state_arrays(ParticleSet<T>&);                                       \
  template StateArrays<T> state_arrays(RigidBodySet<T>&);                                      \
  template class Checkpoint<T>;                                                                \
  template class FiniteScan<T>;                                                                \
  template class StateBuffer<T>;                                                               \
  template void clamp_speeds(T* const[3], const T*, std::size_t, Block, double);               \
  template void clamp_speeds(ParticleSet<T>&, Block, double);                                  \
  template void clamp_speeds(RigidBodySet<T>&, Block, double, double);
KINEMA_GUARD(float)
KINEMA_GUARD(double)
#undef KINEMA_GUARD

}  // namespace kinema
