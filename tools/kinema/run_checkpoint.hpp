#pragma once
// What `kinema run` and `kinema stress` keep in a checkpoint beside the bodies (how far the run
// got, what it has measured so far), and when they write one.

#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace kinema::cli {

// Where to checkpoint and from where to resume (--checkpoint, --checkpoint-every, --resume).
struct CheckpointOptions {
  std::string path;         // empty: none
  double every = 60;        // seconds of wall clock between checkpoints
  std::string resume_path;  // empty: a fresh run

  bool wanted() const { return !path.empty() || !resume_path.empty(); }
};

// A command's own record in a checkpoint's user data: which command and run it belongs to
// (`fingerprint`: the scene file and every option that changes the results), and its fields.
struct RunRecord {
  std::string command;      // "run" or "stress"
  std::string fingerprint;
  nlohmann::json fields;    // numbers whose bits matter go through exact()
};

std::vector<std::byte> encode(const RunRecord& record);
// kinema::Error naming `path` when the data is not a record of `command` with `fingerprint`.
RunRecord decode(std::span<const std::byte> data, const std::string& command, const std::string& fingerprint,
                 const std::string& path);

// A double as its bits, and back: JSON numbers would do, but this says so.
std::uint64_t exact(double value);
double exact(std::uint64_t bits);

// A CRC as the summaries and run records show it: eight hex digits.
std::string crc_text(std::uint32_t crc);

// CRC-32C of the scene file's bytes and of `options` (the results-changing options as text).
std::string fingerprint_of(const std::string& scene_path, const std::string& options);

// A file a command reads or writes, as its option names it ("--summary").
struct NamedPath {
  std::string option, path;
};

// kinema::Error before any work when two outputs are one file, or an output is an input (the
// scene, the --resume file): one would clobber the other. Empty paths are not given. (A
// --resume file may also be the --checkpoint: the run reads it before it writes the next.)
void check_distinct(const std::vector<NamedPath>& inputs, const std::vector<NamedPath>& outputs);
// kinema::Error when a file the run makes by itself (`what`, at `path`) is one of `named`:
// "<what> <path>, the file <option>: one would overwrite the other" (option: "--out names").
void check_apart(const std::string& what, const std::string& path, const std::vector<NamedPath>& named);

// Whether a checkpoint is due: every `every` seconds from construction or the last save().
class CheckpointTimer {
 public:
  explicit CheckpointTimer(const CheckpointOptions& o) : enabled_(!o.path.empty()), every_(o.every) {}
  bool enabled() const { return enabled_; }
  bool due() const {
    return enabled_ && std::chrono::duration<double>(Clock::now() - last_).count() >= every_;
  }
  void saved() { last_ = Clock::now(); }

 private:
  using Clock = std::chrono::steady_clock;
  bool enabled_;
  double every_;
  Clock::time_point last_ = Clock::now();
};

}  // namespace kinema::cli
