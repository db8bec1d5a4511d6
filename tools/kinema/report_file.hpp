#pragma once
// A JSON file for a command's summary or report.

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

#include "kinema/error.hpp"

namespace kinema::cli {

// Opened before the run, so that a path that cannot be written is refused before any work,
// and checked when it is closed (a full disk shows only there).
class ReportFile {
 public:
  ReportFile(const std::string& path, std::string what) : path_(path), what_(std::move(what)) {
    if (path.empty()) return;
    file_ = std::fopen(path.c_str(), "w");
    if (file_ == nullptr) fail();
  }
  ~ReportFile() {
    if (file_ != nullptr) std::fclose(file_);
  }
  ReportFile(const ReportFile&) = delete;
  ReportFile& operator=(const ReportFile&) = delete;
  void write(const nlohmann::ordered_json& summary) {
    if (file_ == nullptr) return;
    const std::string text = summary.dump(2) + "\n";
    const bool written = std::fwrite(text.data(), 1, text.size(), file_) == text.size() &&
                         std::fflush(file_) == 0;
    const int error = errno;
    const bool closed = std::fclose(file_) == 0;
    file_ = nullptr;
    if (!written || !closed) fail(written ? errno : error);
  }

 private:
  [[noreturn]] void fail(int error = errno) const {
    throw Error(printable(path_) + ": cannot write the " + what_ + ": " + std::strerror(error));
  }
  std::string path_, what_;
  std::FILE* file_ = nullptr;
};

}  // namespace kinema::cli
