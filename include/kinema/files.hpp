#pragma once
// Files written whole or not at all, and checksums.

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace kinema {

// 1 or 2 when `path` names the file the process's standard output or error is open on
// (/dev/stdout, /proc/self/fd/2, or that file by its own name), else -1.
int standard_stream_at(const std::filesystem::path& path);

// A file that a reader sees either as it was before or complete, never half written: the
// bytes go to a temporary file beside `path` (same directory, so the rename stays on one
// file system), and commit() flushes and syncs it, renames it over `path` and syncs the
// directory. A WholeFile destroyed without commit() removes its temporary, and `path` keeps
// whatever it held. Construction checks that the directory takes a new file (a path that
// cannot be written is refused before any work); the temporary is made at the first write.
// A device or FIFO that exists at `path` (/dev/null, a pipe) is written directly, and so is
// the file the process's standard output or error is (/dev/stdout when it is redirected to
// a file: replacing that file would lose what the stream wrote). Every failure throws
// kinema::Error naming the path and the reason.
class WholeFile {
 public:
  // `what` names the file in messages ("summary", "checkpoint").
  WholeFile(std::filesystem::path path, std::string what);
  ~WholeFile();
  WholeFile(const WholeFile&) = delete;
  WholeFile& operator=(const WholeFile&) = delete;

  void write(std::span<const std::byte> bytes);
  void write(std::string_view text) { write(std::as_bytes(std::span(text.data(), text.size()))); }
  void commit();
  const std::filesystem::path& path() const { return path_; }
  // Whether `path` is written directly (nothing to rename): a device, a FIFO, or the file a
  // standard stream is open on.
  bool is_device() const { return device_; }

 private:
  [[noreturn]] void fail(const char* doing, int error);
  void open_temporary();

  std::filesystem::path path_, temporary_;
  std::string what_;
  int fd_ = -1;
  unsigned mode_ = 0;  // of the file replaced; 0: a new file
  bool device_ = false, finished_ = false;
  int stream_ = -1;  // 1 or 2: the standard stream written through, flushed before each write
};

// Writes `bytes` to `path` as one WholeFile.
void write_whole_file(const std::filesystem::path& path, std::span<const std::byte> bytes, const std::string& what);

// The regular file at `path`, read whole; kinema::Error for anything else (a directory, a
// FIFO, a device, a file past `max_bytes`), naming the path and `what` it should have been.
std::vector<std::byte> read_regular_file(const std::filesystem::path& path, std::size_t max_bytes,
                                         const std::string& what);

// CRC-32C (the Castagnoli polynomial of iSCSI, ext4 and SSE4.2's crc32 instruction) of
// `bytes`, continuing from `crc` (the CRC of the bytes before them; 0 for none). With SSE4.2
// it runs at several GB/s; without (or use_instruction false) a table gives the same value.
std::uint32_t crc32c(std::span<const std::byte> bytes, std::uint32_t crc = 0, bool use_instruction = true);

}  // namespace kinema
