#include "kinema/error.hpp"

#include <algorithm>
#include <cstdio>
#include <utility>

#include "core/text.hpp"

namespace kinema {

NonFiniteError::NonFiniteError(std::uint64_t step_, double time_, std::size_t body_, std::string field_)
    : Error("the state stops being finite at step " + std::to_string(step_) + " of the call (from t = " +
            shortest_text(time_) + "): body " + std::to_string(body_) + ", " + field_ +
            "; the bodies hold the state before that step"),
      step(step_), time(time_), body(body_), field(std::move(field_)) {}

namespace {

// Length of the valid UTF-8 sequence starting at text[i] (2 to 4), or 0.
std::size_t utf8_length(std::string_view text, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
  const unsigned lead = byte(i);
  std::size_t n = 0;
  unsigned code = 0;
  if (lead >= 0xC2 && lead <= 0xDF) n = 2, code = lead & 0x1F;
  else if (lead >= 0xE0 && lead <= 0xEF) n = 3, code = lead & 0x0F;
  else if (lead >= 0xF0 && lead <= 0xF4) n = 4, code = lead & 0x07;
  else return 0;
  if (i + n > text.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
    code = code << 6 | (byte(i + k) & 0x3F);
  }
  // Overlong forms, surrogates and code points past U+10FFFF are not valid UTF-8.
  const unsigned least[] = {0, 0, 0x80, 0x800, 0x10000};
  if (code < least[n] || (code >= 0xD800 && code <= 0xDFFF) || code > 0x10FFFF) return 0;
  return n;
}

std::string escaped(const char* format, unsigned value) {
  char text[8];
  std::snprintf(text, sizeof text, format, value);
  return text;
}

}  // namespace

std::string printable(std::string_view text, std::size_t limit) {
  std::string out;
  out.reserve(std::min(text.size(), limit));
  for (std::size_t i = 0; i < text.size();) {
    if (out.size() >= limit) {
      return out + "... (" + std::to_string(text.size() - i) + " more bytes)";
    }
    const auto c = static_cast<unsigned char>(text[i]);
    const std::size_t n = c >= 0x80 ? utf8_length(text, i) : 0;
    if (c >= 0x20 && c < 0x7F) {
      out += char(c);
    } else if (n == 0) {
      out += escaped("\\x%02X", c);
    } else if (c == 0xC2 && static_cast<unsigned char>(text[i + 1]) < 0xA0) {
      out += escaped("\\u%04X", static_cast<unsigned char>(text[i + 1]));  // C1 control
    } else {
      out.append(text.substr(i, n));
    }
    i += std::max<std::size_t>(n, 1);
  }
  return out;
}

}  // namespace kinema
