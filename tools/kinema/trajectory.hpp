#pragma once
// Trajectory CSV: step,t,body,px,py,pz,vx,vy,vz with round-trip precision.

#include <cstdint>
#include <cstdio>
#include <string>

#include "kinema/bodies.hpp"

namespace kinema::cli {

class TrajectoryWriter {
 public:
  explicit TrajectoryWriter(const std::string& path);  // throws kinema::Error
  ~TrajectoryWriter();
  TrajectoryWriter(const TrajectoryWriter&) = delete;
  TrajectoryWriter& operator=(const TrajectoryWriter&) = delete;

  template <class T>
  void write(std::uint64_t step, double t, const ParticleSet<T>& bodies);
  void close();  // throws kinema::Error when the data did not reach the file

 private:
  std::FILE* file_ = nullptr;
  std::string path_;
};

}  // namespace kinema::cli
