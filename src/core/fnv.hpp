#pragma once
// FNV-1a, 64 bits, over values' bit patterns: what fingerprints of models and methods are made
// of (equal data, equal hashes on every machine of one byte order).

#include <cstddef>
#include <cstdint>

namespace kinema {

class Fnv {
 public:
  // V: numbers, or arrays of them (no padding bytes, whose contents are unspecified).
  template <class V>
  void add(const V& value) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(&value);
    for (std::size_t i = 0; i < sizeof(V); ++i) hash_ = (hash_ ^ bytes[i]) * 1099511628211ull;
  }
  std::uint64_t value() const { return hash_; }

 private:
  std::uint64_t hash_ = 14695981039346656037ull;
};

}  // namespace kinema
