#include "core/text.hpp"

#include <cstdio>
#include <cstdlib>

namespace kinema {

std::string shortest_text(double x, int digits, bool as_float) {
  char text[32];
  for (int p = 1; p <= digits; ++p) {
    std::snprintf(text, sizeof text, "%.*g", p, x);
    const double back = std::strtod(text, nullptr);
    if (as_float ? float(back) == float(x) : back == x) break;
  }
  return text;
}

}  // namespace kinema
