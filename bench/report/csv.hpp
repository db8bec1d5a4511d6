#pragma once
// The headline rows as CSV (one line per fused rk4 row), for plotting across runs.
#include <cstdio>
#include <string>

#include "rk4_row.hpp"

namespace kinema::bench::report {

class Rk4Csv {
 public:
  // Writes the header; `ok()` is false when the file cannot be written.
  Rk4Csv(const char* path, std::string isa);
  ~Rk4Csv();
  Rk4Csv(const Rk4Csv&) = delete;
  Rk4Csv& operator=(const Rk4Csv&) = delete;

  bool ok() const { return file_ != nullptr; }
  void write(const Rk4Row& row);

 private:
  std::FILE* file_;
  std::string isa_;
};

}  // namespace kinema::bench::report
