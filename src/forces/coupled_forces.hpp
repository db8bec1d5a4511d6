#pragma once
// The coupled terms lowered to the kernels' data, once per stepper: N-body gravity's
// constants in T and the spring network in the kernels' sliced layout. Also their
// potential energies, in double, each pair once.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "kernels/kernels.hpp"
#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "kinema/forces.hpp"

namespace kinema {

template <class T>
struct SpringNetwork {
  std::size_t covered = 0;                  // max index + 1; 0 without springs
  std::vector<std::uint32_t> slice_offset;  // see kernels::SpringJob
  std::vector<std::int32_t> neighbor, contiguous;
  AlignedArray<T> rest, k, damping;
  // The model's pairs (it outlives the network). Their layout, which takes time and memory
  // in proportion to `covered`, is made by lay_out once a set has shown it has those bodies:
  // one spring to body 2^30 - 1 of a 3-body set is refused before anything is built.
  std::span<const SpringPair> pairs;
  bool laid_out = false;

  bool empty() const { return covered == 0; }
  void lay_out();
  std::size_t bytes() const {
    return slice_offset.capacity() * sizeof(std::uint32_t) +
           (neighbor.capacity() + contiguous.capacity()) * sizeof(std::int32_t) +
           (rest.size() + k.size() + damping.size()) * sizeof(T);
  }
  // The kernel's view of it for a stage state; forces go to `force`.
  kernels::SpringJob<T> job(const T* const x[3], const T* const v[3], T* const force[3]) const;
};

template <class T>
struct CoupledForces {
  std::optional<NBody> nbody;  // as given; the kernels get G and softening^2 in T
  T eps2 = 0;
  SpringNetwork<T> springs;
};

// Throws kinema::Error when G or the softening squared overflows T.
template <class T>
CoupledForces<T> lower_coupled(const ForceModel<T>& forces);

// -G sum_{i<j} m_i m_j / sqrt(|x_i - x_j|^2 + softening^2), over bodies with inv_mass != 0.
// Polls `stop` every few million pairs; throws kinema::Stopped once it returns true.
template <class T>
double nbody_potential(const ParticleSet<T>& bodies, const NBody& term, const StopRequest& stop = {});
// Throws kinema::Error when pairs reaching `covered` bodies (the largest index + 1) meet a
// set of fewer.
void check_springs_reach(std::size_t covered, std::size_t bodies);
// sum 1/2 k (|x_i - x_j| - rest)^2 over the pairs; kinema::Error as check_springs_reach for a
// pair past the set (as a step refuses it).
template <class T>
double spring_potential(const ParticleSet<T>& bodies, std::span<const SpringPair> pairs);

}  // namespace kinema
