#pragma once
// Numbers and type names as kinema's messages print them.

#include <string>

namespace kinema {

// "float" or "double".
template <class T>
std::string type_name() {
  return sizeof(T) == 4 ? "float" : "double";
}

// The shortest text, of at most `digits` significant digits, that reads back as the same
// value (as a float when `as_float`): "1e+39", not "9.9999999999999994e+38" nor "0.000000".
std::string shortest_text(double x, int digits = 17, bool as_float = false);
template <class T>
std::string shortest_text(T x) {
  return sizeof(T) == 4 ? shortest_text(double(x), 9, true) : shortest_text(double(x), 17);
}

}  // namespace kinema
