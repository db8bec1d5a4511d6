#pragma once
// A JSON value with the path that leads to it: the scene parser's reading of values, with
// error messages that name the file and the path.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "scene/json_document.hpp"

namespace kinema::scene_json {

struct Node {
  const json& value;
  std::string path;
  std::string_view origin;

  [[noreturn]] void fail(const std::string& what) const {
    throw Error(printable(std::string(origin) + ": " + (path.empty() ? "(top level)" : path) + ": " + what));
  }
  Node child(const std::string& key) const {
    if (!has(key)) fail("missing key '" + key + "'");
    return {value[key], path.empty() ? key : path + "." + key, origin};
  }
  Node element(std::size_t i) const {
    return {value.at(i), path + "[" + std::to_string(i) + "]", origin};
  }
  bool has(const std::string& key) const { return value.contains(key); }

  void expect_object(std::initializer_list<std::string_view> known) const {
    expect_object(std::vector<std::string_view>(known));
  }
  void expect_object(const std::vector<std::string_view>& known) const {
    if (!value.is_object()) fail("expected an object");
    for (const auto& [key, _] : value.items()) {
      if (key == "comment" || key == "description") continue;
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        std::string list;
        for (auto k : known) list += (list.empty() ? "" : ", ") + std::string(k);
        child(key).fail("unknown key (known: " + list + ")");
      }
    }
  }
  double number() const {
    if (!value.is_number()) fail("expected a number");
    const double x = value.get<double>();
    if (!std::isfinite(x)) fail("expected a finite number");
    return x;
  }
  double positive() const {
    const double x = number();
    if (!(x > 0)) fail("expected a number > 0");
    return x;
  }
  double non_negative() const {
    const double x = number();
    if (!(x >= 0)) fail("expected a number >= 0");
    return x;
  }
  std::uint64_t count(bool allow_zero) const {
    // Integers past 2^63 parse as unsigned, negative ones as signed.
    const bool negative = value.is_number_integer() && !value.is_number_unsigned() &&
                          value.get<std::int64_t>() < 0;
    if (!value.is_number_integer() || negative || (!allow_zero && value.get<std::uint64_t>() == 0)) {
      fail(allow_zero ? "expected an integer >= 0" : "expected an integer >= 1");
    }
    return value.get<std::uint64_t>();
  }
  std::string string() const {
    if (!value.is_string()) fail("expected a string");
    return value.get<std::string>();
  }
  bool boolean() const {
    if (!value.is_boolean()) fail("expected true or false");
    return value.get<bool>();
  }
  Vec3<double> vec3() const {
    if (!value.is_array() || value.size() != 3) fail("expected an array of 3 numbers");
    return {element(0).number(), element(1).number(), element(2).number()};
  }
  Node required(const std::string& key) const { return child(key); }
};

}  // namespace kinema::scene_json
