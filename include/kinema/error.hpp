#pragma once
// The one exception type of kinema: thrown at set-up, never from inside a step's kernels.

#include <stdexcept>
#include <string>
#include <string_view>

namespace kinema {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// `text` made safe for one line of a terminal or of a script's string literal: control
// characters (C0, DEL, C1) and bytes that are not valid UTF-8 become \xNN (C1 code points
// \u00NN); every other character, Unicode included, stays as it is. Past `limit` bytes of
// output the rest is left out and counted ("... (N more bytes)").
std::string printable(std::string_view text, std::size_t limit = std::string_view::npos);

}  // namespace kinema
