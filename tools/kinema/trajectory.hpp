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
  // Continues a trajectory a run wrote before: the file is cut back to its first `length`
  // bytes (the length it had at a checkpoint: rows written after it go) and appended to.
  // kinema::Error when it is missing or shorter.
  TrajectoryWriter(const std::string& path, bool rigid_columns, std::uint64_t length);
  ~TrajectoryWriter();
  TrajectoryWriter(const TrajectoryWriter&) = delete;
  TrajectoryWriter& operator=(const TrajectoryWriter&) = delete;

  template <class T>
  void write(std::uint64_t step, double t, const ParticleSet<T>& particles,
             const RigidBodySet<T>& rigid);
  void close();  // throws kinema::Error when the data did not reach the file
  // Flushes and syncs what is written (it survives a crash) and returns the file's length.
  std::uint64_t sync();

 private:
  [[noreturn]] void fail();  // closes the file and throws with errno's reason

  std::FILE* file_ = nullptr;
  bool rigid_columns_ = false;
  std::string path_;
};

}  // namespace kinema::cli
