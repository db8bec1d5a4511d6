#pragma once
// The finiteness guard (StepperOptions::guard): a copy of the state an advance call starts
// from, a scan for the first value that is not finite, and the speed clamp.

#include <array>
#include <atomic>
#include <limits>
#include <cstddef>
#include <optional>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "kinema/job_system.hpp"
#include "parallel/blocks.hpp"

namespace kinema {

// The arrays of a set that a step changes, in the order (and with the names) errors use:
// px .. vz, then for rigid bodies qw .. qz and lx .. lz.
template <class T>
struct StateArrays {
  static constexpr int kMax = 13;
  std::size_t size = 0;    // real bodies
  std::size_t padded = 0;  // elements per array
  int count = 0;
  std::array<T*, kMax> data{};
  std::array<const char*, kMax> names{};
};
template <class T>
StateArrays<T> state_arrays(ParticleSet<T>& bodies);
template <class T>
StateArrays<T> state_arrays(RigidBodySet<T>& bodies);

// The state an advance call starts from, saved block by block.
template <class T>
class Checkpoint {
 public:
  // Grows the copy when the state is larger than any saved before (not thread-safe: call
  // before the blocks run).
  void reserve(const StateArrays<T>& state);
  // Blocks may be saved concurrently; restore puts every block back.
  void save(const StateArrays<T>& state, Block block);
  void restore(const Workers& workers, const StateArrays<T>& state) const;
  std::size_t bytes() const;

 private:
  std::array<AlignedArray<T>, StateArrays<T>::kMax> copy_;
};

// Finds the lowest-numbered body with a value that is not finite, and its first such field,
// over blocks scanned in any order on any thread.
template <class T>
class FiniteScan {
 public:
  explicit FiniteScan(const StateArrays<T>& state) : state_(state) {}
  void scan(Block block);
  std::optional<NonFinite> found() const;

 private:
  const StateArrays<T>& state_;
  std::atomic<std::size_t> lowest_{std::numeric_limits<std::size_t>::max()};
};

// Scales every velocity of the block longer than max_speed down to it (and every angular
// momentum whose angular velocity exceeds max_angular_speed). An infinite component points
// the way; NaN is left for the scan to find.
template <class T>
void clamp_speeds(ParticleSet<T>& bodies, Block block, double max_speed);
template <class T>
void clamp_speeds(RigidBodySet<T>& bodies, Block block, double max_speed, double max_angular_speed);

}  // namespace kinema
