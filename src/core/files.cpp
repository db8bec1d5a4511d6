#include "kinema/files.hpp"

#include <array>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <string>
#include <sys/stat.h>
#include <unistd.h>
#include <nmmintrin.h>

#include "kinema/error.hpp"

namespace kinema {
namespace {

std::atomic<unsigned> next_temporary{0};

// Beside the file a symbolic link points to, so that the rename replaces the file, not the link.
std::filesystem::path resolved(const std::filesystem::path& path) {
  std::error_code ignored;
  const std::filesystem::path real = std::filesystem::weakly_canonical(path, ignored);
  return real.empty() ? path : real;
}

std::filesystem::path temporary_beside(const std::filesystem::path& path) {
  std::string name(1, '.');  // appended piece by piece: GCC 12 warns (-Wrestrict) on "." + string
  name.append(path.filename().string()).append(".tmp-").append(std::to_string(::getpid()));
  name.append("-").append(std::to_string(next_temporary++));
  return path.parent_path() / name;
}

// A new file beside `path`, under a name no other file has: one a process killed while
// writing left (its pid since reused) is passed over. fd < 0 on failure, errno saying why.
std::filesystem::path create_beside(const std::filesystem::path& path, mode_t mode, int& fd) {
  for (int attempt = 0;; ++attempt) {
    std::filesystem::path name = temporary_beside(path);
    fd = ::open(name.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
    if (fd >= 0 || errno != EEXIST || attempt == 1000) return name;
  }
}

// The directory's entry reaches the disk too: without it a crash may lose the rename.
void sync_directory(const std::filesystem::path& file) {
  const std::filesystem::path dir = file.parent_path().empty() ? "." : file.parent_path();
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);  // some file systems refuse a directory sync (EINVAL): the rename stands anyway
  ::close(fd);
}

}  // namespace

int standard_stream_at(const std::filesystem::path& path) {
  struct stat named{};
  if (::stat(path.c_str(), &named) != 0) return -1;
  for (int fd : {1, 2}) {
    struct stat stream{};
    if (::fstat(fd, &stream) == 0 && stream.st_dev == named.st_dev && stream.st_ino == named.st_ino) return fd;
  }
  return -1;
}

WholeFile::WholeFile(std::filesystem::path path, std::string what) : what_(std::move(what)) {
  path_ = resolved(path);
  if (const int stream = standard_stream_at(path); stream >= 0) {
    // Written through the stream's own open file, after what the program printed to it.
    fd_ = ::fcntl(stream, F_DUPFD_CLOEXEC, 0);
    if (fd_ < 0) fail("cannot write", errno);
    device_ = true;
    stream_ = stream;
    return;
  }
  struct stat existing{};
  const bool exists = ::stat(path_.c_str(), &existing) == 0;
  if (exists && S_ISDIR(existing.st_mode)) fail("cannot write", EISDIR);
  if (exists && !S_ISREG(existing.st_mode)) {
    // A device or a FIFO (/dev/stdout, /dev/null) cannot be replaced: it is written as it is.
    // O_NONBLOCK: a FIFO without a reader fails at once (ENXIO) instead of blocking.
    fd_ = ::open(path_.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) fail("cannot write", errno);
    ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL) & ~O_NONBLOCK);
    device_ = true;
    return;
  }
  // A probe now, so that a directory that cannot be written is refused before any work; the
  // temporary itself is made at the first write, so that a process killed before it leaves
  // nothing behind.
  const std::filesystem::path probe = create_beside(path_, 0600, fd_);
  if (fd_ < 0) fail("cannot write", errno);
  ::close(fd_), ::unlink(probe.c_str());
  fd_ = -1;
  mode_ = exists ? existing.st_mode & 07777 : 0;
}

void WholeFile::open_temporary() {
  temporary_ = create_beside(path_, 0666, fd_);
  if (fd_ < 0) {
    temporary_.clear();
    fail("cannot write", errno);
  }
  if (mode_ != 0) ::fchmod(fd_, mode_);  // the file it replaces keeps its mode
}

WholeFile::~WholeFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!temporary_.empty()) ::unlink(temporary_.c_str());
}

void WholeFile::fail(const char* doing, int error) {
  finished_ = true;  // unsuccessfully: nothing more goes in
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!temporary_.empty()) ::unlink(temporary_.c_str());
  temporary_.clear();
  throw Error(printable(path_.string()) + ": " + doing + " the " + what_ + ": " + std::strerror(error));
}

void WholeFile::write(std::span<const std::byte> bytes) {
  if (finished_) throw Error(printable(path_.string()) + ": the " + what_ + " is already written, or failed");
  if (fd_ < 0) open_temporary();
  if (stream_ >= 0) std::fflush(stream_ == 1 ? stdout : stderr);
  while (!bytes.empty()) {
    const ssize_t n = ::write(fd_, bytes.data(), bytes.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot write", n < 0 ? errno : ENOSPC);
    bytes = bytes.subspan(std::size_t(n));
  }
}

void WholeFile::commit() {
  if (finished_) throw Error(printable(path_.string()) + ": the " + what_ + " is already written, or failed");
  if (fd_ < 0) open_temporary();  // nothing written: an empty file
  finished_ = true;
  if (device_) {  // nothing to rename
    const int error = ::close(fd_) == 0 ? 0 : errno;
    fd_ = -1;
    if (error != 0) fail("cannot write", error);
    return;
  }
  if (::fsync(fd_) != 0) fail("cannot sync", errno);
  const int error = ::close(fd_) == 0 ? 0 : errno;
  fd_ = -1;
  if (error != 0) fail("cannot write", error);
  if (::rename(temporary_.c_str(), path_.c_str()) != 0) fail("cannot rename into place", errno);
  temporary_.clear();
  sync_directory(path_);
}

void write_whole_file(const std::filesystem::path& path, std::span<const std::byte> bytes, const std::string& what) {
  WholeFile file(path, what);
  file.write(bytes);
  file.commit();
}

std::vector<std::byte> read_regular_file(const std::filesystem::path& path, std::size_t max_bytes,
                                         const std::string& what) {
  const auto fail = [&](const std::string& why) {
    return Error(printable(path.string()) + ": cannot read the " + what + ": " + why);
  };
  // O_NONBLOCK: opening a FIFO without a writer must not wait for one.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw fail(std::strerror(errno));
  struct stat st{};
  const bool stated = ::fstat(fd, &st) == 0;
  std::string refusal = !stated                ? std::strerror(errno)
                        : S_ISDIR(st.st_mode)  ? "it is a directory"
                        : !S_ISREG(st.st_mode) ? "it is not a regular file"
                        : std::size_t(st.st_size) > max_bytes
                            ? std::to_string(st.st_size) + " bytes, more than the " + std::to_string(max_bytes) + " allowed"
                            : "";
  if (!refusal.empty()) {
    ::close(fd);
    throw fail(refusal);
  }
  std::vector<std::byte> data(std::size_t(st.st_size));
  std::size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::read(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int error = errno;
      ::close(fd);
      throw fail(std::strerror(error));
    }
    if (n == 0) break;  // shorter than fstat said: it changed under us; the caller checks lengths
    done += std::size_t(n);
  }
  ::close(fd);
  data.resize(done);
  return data;
}

namespace {

// CRC-32C, reflected: polynomial 0x1EDC6F41 bit-reversed.
constexpr std::uint32_t kCastagnoli = 0x82F63B78u;

// Slicing by 8: table[k][b] is the CRC of byte b followed by k zero bytes.
constexpr std::array<std::array<std::uint32_t, 256>, 8> make_tables() {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  for (std::uint32_t b = 0; b < 256; ++b) {
    std::uint32_t c = b;
    for (int bit = 0; bit < 8; ++bit) c = c & 1 ? (c >> 1) ^ kCastagnoli : c >> 1;
    t[0][b] = c;
  }
  for (std::size_t k = 1; k < 8; ++k) {
    for (std::size_t b = 0; b < 256; ++b) t[k][b] = (t[k - 1][b] >> 8) ^ t[0][t[k - 1][b] & 0xFF];
  }
  return t;
}
constexpr auto kTables = make_tables();

std::uint32_t crc32c_tables(const unsigned char* p, std::size_t n, std::uint32_t c) {
  for (; n >= 8; p += 8, n -= 8) {
    std::uint64_t v;
    std::memcpy(&v, p, 8);
    v ^= c;
    c = kTables[7][v & 0xFF] ^ kTables[6][(v >> 8) & 0xFF] ^ kTables[5][(v >> 16) & 0xFF] ^
        kTables[4][(v >> 24) & 0xFF] ^ kTables[3][(v >> 32) & 0xFF] ^ kTables[2][(v >> 40) & 0xFF] ^
        kTables[1][(v >> 48) & 0xFF] ^ kTables[0][v >> 56];
  }
  for (; n > 0; ++p, --n) c = (c >> 8) ^ kTables[0][(c ^ *p) & 0xFF];
  return c;
}

// a b mod P in the reflected order (bit 31 holds x^0): what advances a CRC register over zeros.
std::uint32_t multiply_mod(std::uint32_t a, std::uint32_t b) {
  std::uint32_t product = 0;
  for (int i = 0; i < 32; ++i, a <<= 1) {
    if (a & 0x80000000u) product ^= b;
    b = b & 1 ? (b >> 1) ^ kCastagnoli : b >> 1;  // b x, reduced
  }
  return product;
}

// x^(8 n) mod P: a register times it is the register run over n zero bytes.
std::uint32_t zeros_operator(std::size_t n) {
  std::uint32_t result = 0x80000000u, square = 0x00800000u;  // x^0 and x^8
  for (; n > 0; n >>= 1, square = multiply_mod(square, square)) {
    if (n & 1) result = multiply_mod(result, square);
  }
  return result;
}

[[gnu::target("sse4.2")]] std::uint64_t crc32c_words(std::uint64_t c, const unsigned char* p, std::size_t words) {
  for (std::size_t i = 0; i < words; ++i, p += 8) {
    std::uint64_t v;
    std::memcpy(&v, p, 8);
    c = _mm_crc32_u64(c, v);
  }
  return c;
}

// SSE4.2's crc32 instruction computes the same polynomial, 8 bytes at a time. One register
// waits 3 cycles for each word: three run side by side over thirds of the data, and the
// register being linear, each is advanced over the bytes after its third and they are added.
[[gnu::target("sse4.2")]] std::uint32_t crc32c_sse42(const unsigned char* p, std::size_t n, std::uint32_t c) {
  constexpr std::size_t kInterleaveFrom = 3 * 256;
  if (n >= kInterleaveFrom) {
    const std::size_t third = n / 24 * 8;  // bytes per stream, whole words
    const unsigned char* q = p + third;
    const unsigned char* r = q + third;
    std::uint64_t a = c, b = 0, d = 0;
    for (std::size_t i = 0; i < third; i += 8) {
      std::uint64_t u, v, w;
      std::memcpy(&u, p + i, 8), std::memcpy(&v, q + i, 8), std::memcpy(&w, r + i, 8);
      a = _mm_crc32_u64(a, u), b = _mm_crc32_u64(b, v), d = _mm_crc32_u64(d, w);
    }
    const std::uint32_t shift = zeros_operator(third);
    c = multiply_mod(multiply_mod(std::uint32_t(a), shift) ^ std::uint32_t(b), shift) ^ std::uint32_t(d);
    p += 3 * third, n -= 3 * third;
  }
  c = std::uint32_t(crc32c_words(c, p, n / 8));
  p += n / 8 * 8, n %= 8;
  for (; n > 0; ++p, --n) c = _mm_crc32_u8(c, *p);
  return c;
}

}  // namespace

std::uint32_t crc32c(std::span<const std::byte> bytes, std::uint32_t crc, bool use_instruction) {
  static const bool has_sse42 = __builtin_cpu_supports("sse4.2");
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const std::uint32_t c = ~crc;
  return ~(use_instruction && has_sse42 ? crc32c_sse42(p, bytes.size(), c) : crc32c_tables(p, bytes.size(), c));
}

}  // namespace kinema
