#include "trajectory.hpp"

#include <cerrno>
#include <cstdio>
#include <fcntl.h>
#include <cstring>
#include <sys/stat.h>
#include <unistd.h>

#include "kinema/error.hpp"
#include "kinema/files.hpp"
#include "numbers.hpp"

namespace kinema::cli {

namespace {

// The trajectory's file: the standard stream's own open file where the path names it (so
// that the stream's lines and the trajectory's follow one another), a FIFO only if a reader
// has it open (never blocking), else a file truncated or made.
int open_trajectory(const std::string& path) {
  if (const int stream = standard_stream_at(path); stream >= 0) {
    std::fflush(stream == 1 ? stdout : stderr);
    return ::fcntl(stream, F_DUPFD_CLOEXEC, 0);
  }
  struct stat st{};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd >= 0) ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
    return fd;
  }
  return ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
}

}  // namespace

TrajectoryWriter::TrajectoryWriter(const std::string& path, bool rigid_columns)
    : rigid_columns_(rigid_columns), path_(path) {
  const int fd = open_trajectory(path);
  file_ = fd < 0 ? nullptr : ::fdopen(fd, "w");
  if (file_ == nullptr) {
    const int error = errno;
    if (fd >= 0) ::close(fd);
    struct stat st{};
    const bool fifo = ::stat(path.c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
    throw Error(printable(path) + ": cannot write the trajectory: " +
                (error == ENXIO && fifo ? std::string("a FIFO that no reader has open") : std::strerror(error)));
  }
  std::fputs(rigid_columns ? "step,t,body,px,py,pz,vx,vy,vz,qw,qx,qy,qz,lx,ly,lz\n"
                           : "step,t,body,px,py,pz,vx,vy,vz\n",
             file_);
  // The header reaches the file before the run: a full device is found here, not at the end.
  if (std::fflush(file_) != 0) fail();
}

TrajectoryWriter::TrajectoryWriter(const std::string& path, bool rigid_columns, std::uint64_t length)
    : rigid_columns_(rigid_columns), path_(path) {
  file_ = std::fopen(path.c_str(), "r+");
  if (file_ == nullptr) {
    throw Error(printable(path) + ": cannot continue the trajectory: " + std::strerror(errno));
  }
  struct stat st{};
  if (::fstat(::fileno(file_), &st) != 0 || !S_ISREG(st.st_mode) || std::uint64_t(st.st_size) < length) {
    std::fclose(file_);
    file_ = nullptr;
    throw Error(printable(path) + ": cannot continue the trajectory: it is not a file of at least the " +
                std::to_string(length) + " bytes it had at the checkpoint");
  }
  if (::ftruncate(::fileno(file_), off_t(length)) != 0 || std::fseek(file_, 0, SEEK_END) != 0) fail();
}

std::uint64_t TrajectoryWriter::sync() {
  if (std::fflush(file_) != 0 || ::fdatasync(::fileno(file_)) != 0) fail();
  const long length = std::ftell(file_);
  if (length < 0) fail();
  return std::uint64_t(length);
}

void TrajectoryWriter::fail() {
  const int error = errno;
  std::fclose(file_);
  file_ = nullptr;
  throw Error(printable(path_) + ": cannot write the trajectory: " + std::strerror(error));
}

TrajectoryWriter::~TrajectoryWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

namespace {

template <class T>
void write_centre(std::FILE* f, std::uint64_t step, double t, std::size_t body,
                  const ParticleSet<T>& b, std::size_t i) {
  std::fprintf(f, "%llu,%.17g,%zu", static_cast<unsigned long long>(step), t, body);
  for (const T* a : {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()}) {
    std::fprintf(f, kRoundTripColumn<T>, double(a[i]));
  }
}

}  // namespace

template <class T>
void TrajectoryWriter::write(std::uint64_t step, double t, const ParticleSet<T>& particles,
                             const RigidBodySet<T>& rigid) {
  for (std::size_t i = 0; i < particles.size(); ++i) {
    write_centre(file_, step, t, i, particles, i);
    std::fputs(rigid_columns_ ? ",,,,,,,\n" : "\n", file_);
  }
  for (std::size_t i = 0; i < rigid.size(); ++i) {
    write_centre(file_, step, t, particles.size() + i, rigid.centers(), i);
    for (int k = 0; k < 4; ++k) std::fprintf(file_, kRoundTripColumn<T>, double(rigid.q(k)[i]));
    for (int d = 0; d < 3; ++d) std::fprintf(file_, kRoundTripColumn<T>, double(rigid.l(d)[i]));
    std::fputc('\n', file_);
  }
  if (std::ferror(file_) != 0) fail();  // stop at the first failed write, not at the end
}

void TrajectoryWriter::close() {
  if (std::fflush(file_) != 0 || std::ferror(file_) != 0) fail();
  const bool closed = std::fclose(file_) == 0;
  file_ = nullptr;
  if (!closed) throw Error(printable(path_) + ": cannot write the trajectory: " + std::strerror(errno));
}

template void TrajectoryWriter::write(std::uint64_t, double, const ParticleSet<float>&,
                                      const RigidBodySet<float>&);
template void TrajectoryWriter::write(std::uint64_t, double, const ParticleSet<double>&,
                                      const RigidBodySet<double>&);

}  // namespace kinema::cli
