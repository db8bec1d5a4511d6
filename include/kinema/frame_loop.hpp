#pragma once
// A fixed-timestep frame loop ("Fix Your Timestep"): whole steps of h from the frames' wall
// times, and drawing between the last two states.
//
//   kinema::FixedTimestep clock(1.0 / 60);
//   each frame:
//     for (unsigned k = clock.steps_for(frame_seconds); k > 0; --k) {
//       previous = current;            // reuses previous's memory
//       stepper.step(current, clock.step_size());
//     }
//     kinema::interpolate(previous, current, clock.alpha(), drawn);

#include <cstdint>
#include <type_traits>

#include "kinema/bodies.hpp"
#include "kinema/isa.hpp"

namespace kinema {

class FixedTimestep {
 public:
  // h > 0 with a finite 1 / h; max_steps_per_frame >= 1 (kinema::Error otherwise).
  explicit FixedTimestep(double h, unsigned max_steps_per_frame = 8);

  // Adds a frame's wall time (finite, >= 0) and returns how many steps of h to run now. At
  // most max_steps_per_frame: a slow frame must not ask for more steps than the next frame
  // can run (the spiral of death), so time past the cap is dropped and the simulation falls
  // behind the wall clock instead.
  unsigned steps_for(double frame_seconds);
  // The time accumulated but not stepped, as a fraction of h in [0, 1): where to draw
  // between the previous and the current state.
  double alpha() const { return accumulated_ / h_; }
  double step_size() const { return h_; }
  // Steps dropped by the cap so far (saturating at 2^64 - 1).
  std::uint64_t dropped_steps() const { return dropped_; }

 private:
  double h_;
  unsigned cap_;
  double accumulated_ = 0;
  std::uint64_t dropped_ = 0;
};

// out = previous + alpha (current - previous) for positions; for rigid bodies also the
// normalized lerp of orientations along the short arc. Velocities, masses and the rest come
// from `current`. The two sets must hold the same bodies (same size; kinema::Error
// otherwise); `out` is made a copy of `current` first, which reuses its memory when it is
// large enough, so a frame loop allocates only at its first frame. SIMD over bodies on the
// best instruction set (or `isa`).
// `out` may not be `previous` or `current`, and alpha must be finite (kinema::Error).
template <class T>
void interpolate(const ParticleSet<T>& previous, const ParticleSet<T>& current,
                 std::type_identity_t<T> alpha, ParticleSet<T>& out, Isa isa = Isa::automatic);
template <class T>
void interpolate(const RigidBodySet<T>& previous, const RigidBodySet<T>& current,
                 std::type_identity_t<T> alpha, RigidBodySet<T>& out, Isa isa = Isa::automatic);

}  // namespace kinema
