#include "kinema/frame_loop.hpp"

#include <cmath>
#include <limits>
#include <string>

#include "kernels/kernels.hpp"
#include "kinema/error.hpp"
#include "step/step_context.hpp"

namespace kinema {

FixedTimestep::FixedTimestep(double h, unsigned max_steps_per_frame) : h_(h), cap_(max_steps_per_frame) {
  if (!(std::isfinite(h) && h > 0 && std::isfinite(1 / h))) {
    throw Error("fixed timestep: h must be positive and finite, and so must 1 / h");
  }
  if (max_steps_per_frame == 0) throw Error("fixed timestep: at least one step per frame");
}

unsigned FixedTimestep::steps_for(double frame_seconds) {
  if (!(std::isfinite(frame_seconds) && frame_seconds >= 0)) {
    throw Error("fixed timestep: a frame's time must be finite and >= 0");
  }
  accumulated_ += frame_seconds;
  const double due = std::floor(accumulated_ / h_);
  const unsigned steps = due >= double(cap_) ? cap_ : unsigned(due);
  if (due > double(cap_)) {
    // Saturated, the frame's and the total: 2^64 steps is forever anyway, and must not wrap.
    constexpr std::uint64_t most = std::numeric_limits<std::uint64_t>::max();
    const double dropped = due - double(cap_);
    const std::uint64_t now = dropped < 0x1p64 ? std::uint64_t(dropped) : most;
    dropped_ = dropped_ > most - now ? most : dropped_ + now;
    accumulated_ = std::isfinite(accumulated_) ? std::fmod(accumulated_, h_) : 0.0;  // keep the fraction
  } else {
    accumulated_ -= double(steps) * h_;
  }
  accumulated_ = std::min(std::max(accumulated_, 0.0), std::nextafter(h_, 0.0));
  return steps;
}

namespace {

template <class Set, class T>
void check_pair(const Set& previous, const Set& current, const Set& out, T alpha) {
  if (&out == &previous || &out == &current) throw Error("interpolate: out must be a set of its own");
  if (!std::isfinite(alpha)) throw Error("interpolate: alpha must be finite");  // else every position is NaN
  if (previous.size() != current.size()) {
    throw Error("interpolate: the previous set has " + std::to_string(previous.size()) +
                " bodies, the current one " + std::to_string(current.size()));
  }
}

template <class T>
kernels::InterpolateJob<T> position_job(const ParticleSet<T>& previous, const ParticleSet<T>& current,
                                        T* const out[3], T alpha) {
  kernels::InterpolateJob<T> job{};
  job.previous[0] = previous.px(), job.previous[1] = previous.py(), job.previous[2] = previous.pz();
  job.current[0] = current.px(), job.current[1] = current.py(), job.current[2] = current.pz();
  for (int d = 0; d < 3; ++d) job.out[d] = out[d];
  job.alpha = alpha;
  return job;
}

}  // namespace

template <class T>
void interpolate(const ParticleSet<T>& previous, const ParticleSet<T>& current,
                 std::type_identity_t<T> alpha, ParticleSet<T>& out, Isa isa) {
  check_pair(previous, current, out, alpha);
  const auto& table = kernels::kernel_table<T>(isa);  // may throw: before out changes
  out = current;
  T* const positions[3] = {out.px(), out.py(), out.pz()};
  table.interpolate(position_job(previous, current, positions, alpha), 0, out.padded_size());
}

template <class T>
void interpolate(const RigidBodySet<T>& previous, const RigidBodySet<T>& current,
                 std::type_identity_t<T> alpha, RigidBodySet<T>& out, Isa isa) {
  check_pair(previous, current, out, alpha);
  const auto& table = kernels::kernel_table<T>(isa);
  out = current;
  T* const positions[3] = {out.position_data(0), out.position_data(1), out.position_data(2)};
  kernels::InterpolateJob<T> job = position_job(previous.centers(), current.centers(), positions, alpha);
  for (int k = 0; k < 4; ++k) job.previous_q[k] = previous.q(k), job.current_q[k] = current.q(k), job.out_q[k] = out.q(k);
  table.interpolate(job, 0, out.padded_size());
}

template void interpolate<float>(const ParticleSet<float>&, const ParticleSet<float>&, float, ParticleSet<float>&, Isa);
template void interpolate<double>(const ParticleSet<double>&, const ParticleSet<double>&, double, ParticleSet<double>&, Isa);
template void interpolate<float>(const RigidBodySet<float>&, const RigidBodySet<float>&, float, RigidBodySet<float>&, Isa);
template void interpolate<double>(const RigidBodySet<double>&, const RigidBodySet<double>&, double, RigidBodySet<double>&, Isa);

}  // namespace kinema
