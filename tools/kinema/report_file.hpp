#pragma once
// A JSON file for a command's summary or report, written whole (kinema/files.hpp).

#include <optional>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "kinema/files.hpp"

namespace kinema::cli {

// Opened before the run, so that a path that cannot be written is refused before any work.
// Until write() the earlier file, if any, stays as it was; write() replaces it whole, once.
class ReportFile {
 public:
  // A device (/dev/stdout, /dev/full) gets a newline at once, whitespace JSON allows before a
  // value: a full device or a closed pipe is found now, not after the run.
  ReportFile(const std::string& path, const std::string& what) {
    if (path.empty()) return;
    file_.emplace(path, what);
    if (file_->is_device()) file_->write(std::string_view("\n"));
  }
  void write(const nlohmann::ordered_json& summary) {
    written_ = true;
    if (!file_) return;
    file_->write(summary.dump(2) + "\n");
    file_->commit();
  }
  bool written() const { return written_; }

 private:
  std::optional<WholeFile> file_;
  bool written_ = false;
};

}  // namespace kinema::cli
