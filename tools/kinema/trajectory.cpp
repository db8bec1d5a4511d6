#include "trajectory.hpp"

#include <cerrno>
#include <cstring>

#include "kinema/error.hpp"

namespace kinema::cli {

TrajectoryWriter::TrajectoryWriter(const std::string& path) : path_(path) {
  file_ = std::fopen(path.c_str(), "w");
  if (file_ == nullptr) {
    throw Error(path + ": cannot write the trajectory: " + std::strerror(errno));
  }
  std::fputs("step,t,body,px,py,pz,vx,vy,vz\n", file_);
}

TrajectoryWriter::~TrajectoryWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

template <class T>
void TrajectoryWriter::write(std::uint64_t step, double t, const ParticleSet<T>& b) {
  // %.9g and %.17g are the shortest fixed widths that round-trip float and double.
  const char* row = sizeof(T) == 4 ? "%llu,%.17g,%zu,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n"
                                   : "%llu,%.17g,%zu,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n";
  for (std::size_t i = 0; i < b.size(); ++i) {
    std::fprintf(file_, row, static_cast<unsigned long long>(step), t, i, double(b.px()[i]),
                 double(b.py()[i]), double(b.pz()[i]), double(b.vx()[i]), double(b.vy()[i]),
                 double(b.vz()[i]));
  }
}

void TrajectoryWriter::close() {
  const bool failed = std::ferror(file_) != 0;
  const bool close_failed = std::fclose(file_) != 0;
  file_ = nullptr;
  if (failed || close_failed) throw Error(path_ + ": writing the trajectory failed");
}

template void TrajectoryWriter::write(std::uint64_t, double, const ParticleSet<float>&);
template void TrajectoryWriter::write(std::uint64_t, double, const ParticleSet<double>&);

}  // namespace kinema::cli
