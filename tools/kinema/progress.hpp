#pragma once
// A progress bar on stderr for work that runs longer than about a second; silent when
// stderr is not a terminal or when asked to be quiet.

#include <chrono>
#include <cstdio>
#include <string>
#include <unistd.h>

namespace kinema::cli {

class Progress {
 public:
  Progress(std::string label, bool quiet)
      : label_(std::move(label)), enabled_(!quiet && ::isatty(STDERR_FILENO) == 1),
        start_(std::chrono::steady_clock::now()) {}
  ~Progress() { finish(); }

  void update(double fraction) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (now - start_ < std::chrono::seconds(1) || now - last_ < std::chrono::milliseconds(100)) {
      return;
    }
    last_ = now;
    const int filled = int(fraction * 30 + 0.5);
    std::fprintf(stderr, "\r%s [%-30s] %3d%%", label_.c_str(), std::string(filled, '#').c_str(),
                 int(fraction * 100 + 0.5));
    shown_ = true;
  }
  void finish() {
    if (shown_) std::fprintf(stderr, "\r%*s\r", int(label_.size()) + 38, "");
    shown_ = false;
  }

 private:
  std::string label_;
  bool enabled_;
  bool shown_ = false;
  std::chrono::steady_clock::time_point start_, last_{};
};

}  // namespace kinema::cli
