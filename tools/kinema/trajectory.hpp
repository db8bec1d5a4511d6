#pragma once
// Trajectory CSV: step,t,body,px,py,pz,vx,vy,vz with round-trip precision; scenes with
// rigid bodies add qw,qx,qy,qz,lx,ly,lz (empty on particle rows). Particles are numbered
// first, then rigid bodies.

#include <cstdint>
#include <cstdio>
#include <string>

#include "kinema/bodies.hpp"

namespace kinema::cli {

class TrajectoryWriter {
 public:
  // Throws kinema::Error when the file cannot be written (the header is flushed at once).
  // write() and close() throw at the first write that fails.
  TrajectoryWriter(const std::string& path, bool rigid_columns);
  ~TrajectoryWriter();
  TrajectoryWriter(const TrajectoryWriter&) = delete;
  TrajectoryWriter& operator=(const TrajectoryWriter&) = delete;

  template <class T>
  void write(std::uint64_t step, double t, const ParticleSet<T>& particles,
             const RigidBodySet<T>& rigid);
  void close();  // throws kinema::Error when the data did not reach the file

 private:
  [[noreturn]] void fail();  // closes the file and throws with errno's reason

  std::FILE* file_ = nullptr;
  bool rigid_columns_ = false;
  std::string path_;
};

}  // namespace kinema::cli
