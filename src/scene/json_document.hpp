#pragma once
// A scene file's text read into a JSON document with paths: an error the JSON library finds
// (a number out of range, a syntax error), a repeated key or nesting past 64 levels is a
// kinema::Error naming the file and the path.

#include <string_view>

#include <nlohmann/json.hpp>

namespace kinema::scene_json {

using json = nlohmann::json;

json parse_json(std::string_view text, std::string_view origin);

}  // namespace kinema::scene_json
