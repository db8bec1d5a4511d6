#include "finite_guard.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>

#include "blocks.hpp"

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

// The first index in [begin, end) whose value is not finite, or end. The loop without an
// early exit vectorizes; the exact index is looked up only in a block that has one.
template <class T>
std::size_t first_bad(const T* a, std::size_t begin, std::size_t end) {
  bool any = false;
  for (std::size_t i = begin; i < end; ++i) any |= !(std::abs(a[i]) <= std::numeric_limits<T>::max());
  if (!any) return end;
  for (std::size_t i = begin; i < end; ++i) {
    if (!std::isfinite(a[i])) return i;
  }
  return end;
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
void Checkpoint<T>::save(GuardJobs where, const StateArrays<T>& s) {
  for (int a = 0; a < s.count; ++a) {
    if (copy_[a].size() < s.padded) copy_[a] = AlignedArray<T>(s.padded);
  }
  for_each_block(where.jobs, where.parallel, s.padded, [&](Block b) {
    for (int a = 0; a < s.count; ++a) {
      std::memcpy(copy_[a].data() + b.begin, s.data[a] + b.begin, (b.end - b.begin) * sizeof(T));
    }
  });
}

template <class T>
void Checkpoint<T>::restore(GuardJobs where, const StateArrays<T>& s) const {
  for_each_block(where.jobs, where.parallel, s.padded, [&](Block b) {
    for (int a = 0; a < s.count; ++a) {
      std::memcpy(s.data[a] + b.begin, copy_[a].data() + b.begin, (b.end - b.begin) * sizeof(T));
    }
  });
}

template <class T>
std::size_t Checkpoint<T>::bytes() const {
  std::size_t n = 0;
  for (const auto& a : copy_) n += a.size() * sizeof(T);
  return n;
}

template <class T>
std::optional<NonFinite> scan_non_finite(GuardJobs where, const StateArrays<T>& s) {
  std::atomic<std::size_t> lowest{kNoKey};
  for_each_block(where.jobs, where.parallel, s.size, [&](Block b) {
    for (int a = 0; a < s.count; ++a) {
      const std::size_t i = first_bad(s.data[a], b.begin, b.end);
      if (i < b.end) keep_lowest(lowest, key(i, a));
    }
  });
  const std::size_t k = lowest.load();
  if (k == kNoKey) return std::nullopt;
  return NonFinite{k / StateArrays<T>::kMax, s.names[k % StateArrays<T>::kMax]};
}

template <class T>
void clamp_speeds(GuardJobs where, ParticleSet<T>& b, double max_speed) {
  T *vx = b.vx(), *vy = b.vy(), *vz = b.vz();
  const T* inv_mass = b.inv_mass();
  for_each_block(where.jobs, where.parallel, b.size(), [&](Block block) {
    for (std::size_t i = block.begin; i < block.end; ++i) {
      if (inv_mass[i] != 0) clamp(vx[i], vy[i], vz[i], max_speed);
    }
  });
}

template <class T>
void clamp_speeds(GuardJobs where, RigidBodySet<T>& b, double max_speed, double max_angular_speed) {
  T *vx = b.velocity_data(0), *vy = b.velocity_data(1), *vz = b.velocity_data(2);
  T *lx = b.l(0), *ly = b.l(1), *lz = b.l(2);
  const T* inv_mass = b.centers().inv_mass();
  for_each_block(where.jobs, where.parallel, b.size(), [&](Block block) {
    for (std::size_t i = block.begin; i < block.end; ++i) {
      if (inv_mass[i] != 0) clamp(vx[i], vy[i], vz[i], max_speed);
      // omega is linear in L: first give an infinite L a direction, then scale it.
      clamp(lx[i], ly[i], lz[i], double(std::numeric_limits<T>::max()));
      const Vec3<double> w = b.angular_velocity(i);
      const double speed = length(w[0], w[1], w[2]);
      if (speed > max_angular_speed) {
        const double scale = max_angular_speed / speed;
        lx[i] = T(lx[i] * scale), ly[i] = T(ly[i] * scale), lz[i] = T(lz[i] * scale);
      }
    }
  });
}

#define KINEMA_GUARD(T)                                                                        \
  template StateArrays<T> state_arrays(ParticleSet<T>&);                                       \
  template StateArrays<T> state_arrays(RigidBodySet<T>&);                                      \
  template class Checkpoint<T>;                                                                \
  template std::optional<NonFinite> scan_non_finite(GuardJobs, const StateArrays<T>&);         \
  template void clamp_speeds(GuardJobs, ParticleSet<T>&, double);                              \
  template void clamp_speeds(GuardJobs, RigidBodySet<T>&, double, double);
KINEMA_GUARD(float)
KINEMA_GUARD(double)
#undef KINEMA_GUARD

}  // namespace kinema
