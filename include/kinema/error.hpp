#pragma once
// The one exception type of kinema: thrown at set-up, never from inside a step's kernels.

#include <stdexcept>
#include <string>

namespace kinema {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace kinema
