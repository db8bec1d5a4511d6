#pragma once
// The finiteness guard (StepperOptions::guard): a copy of the state an advance call starts
// from, a scan for the first value that is not finite, and the speed clamp.

#include <array>
#include <atomic>
#include <limits>
#include <cstddef>
#include <optional>
#include <vector>

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
  // Grows the copy when the state is larger than any saved before, and starts a call: no
  // block saved yet (not thread-safe: call before the blocks run).
  void reserve(const StateArrays<T>& state);
  // Blocks may be saved concurrently; restore puts back every block saved since reserve (a
  // block a throw kept from starting was neither saved nor changed).
  void save(const StateArrays<T>& state, Block block);
  void restore(const Workers& workers, const StateArrays<T>& state) const;
  std::size_t bytes() const;

 private:
  std::array<AlignedArray<T>, StateArrays<T>::kMax> copy_;
  std::vector<std::uint64_t> saved_in_;  // per block: the call that saved it
  std::uint64_t call_ = 0;
};

// Where a guarded call on the fused particle path writes: a second copy of the set's
// px .. vz. Each block's first step reads the set and writes here, in one pass; the block is
// scanned while in cache; when every block is finite the set takes these arrays and gives
// its own (a swap of pointers, so the set's state pointers change with each call), the next
// call's buffer. Nothing is copied, and nothing is put back when a value is not finite: the
// set was never written.
template <class T>
class StateBuffer {
 public:
  // Sized as the set's arrays (allocates when the set's capacity changed).
  void reserve(const ParticleSet<T>& set);
  // The buffer's arrays, as state_arrays(set) names them, for a call to write up to the
  // set's padded size.
  StateArrays<T> arrays(const ParticleSet<T>& set);
  void swap_into(ParticleSet<T>& set);
  std::size_t bytes() const;

 private:
  std::array<AlignedArray<T>, 6> copy_;
  // The buffer's elements past the set's padded size are zero up to here: a set that shrank
  // leaves old state there, which must not become its padding.
  std::size_t written_end_ = 0;
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
// The same on velocity arrays of the set's size and masses (the guard's buffer).
template <class T>
void clamp_speeds(T* const velocity[3], const T* inv_mass, std::size_t size, Block block, double max_speed);
template <class T>
void clamp_speeds(RigidBodySet<T>& bodies, Block block, double max_speed, double max_angular_speed);

}  // namespace kinema
