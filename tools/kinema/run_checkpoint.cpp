#include "run_checkpoint.hpp"

#include <bit>
#include <cstdio>

#include "kinema/error.hpp"
#include "kinema/files.hpp"
#include "kinema/scene.hpp"

namespace kinema::cli {

std::vector<std::byte> encode(const RunRecord& record) {
  const nlohmann::json j = {{"command", record.command}, {"fingerprint", record.fingerprint}, {"fields", record.fields}};
  const std::string text = j.dump();
  const auto* bytes = reinterpret_cast<const std::byte*>(text.data());
  return {bytes, bytes + text.size()};
}

RunRecord decode(std::span<const std::byte> data, const std::string& command, const std::string& fingerprint,
                 const std::string& path) {
  const std::string where = printable(path) + ": ";
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(reinterpret_cast<const char*>(data.data()), reinterpret_cast<const char*>(data.data()) + data.size());
  } catch (const nlohmann::json::exception&) {
    throw Error(where + "not a checkpoint of kinema " + command + " (no run record)");
  }
  if (!j.is_object() || !j.contains("command") || !j["command"].is_string() || !j.contains("fields") ||
      !j["fields"].is_object() || !j.contains("fingerprint") || !j["fingerprint"].is_string()) {
    throw Error(where + "not a checkpoint of kinema " + command + " (no run record)");
  }
  if (j["command"] != command) {
    throw Error(where + "a checkpoint of kinema " + printable(j["command"].get<std::string>()) + ", not of kinema " + command);
  }
  if (j["fingerprint"] != fingerprint) {
    throw Error(where + "taken under another scene or other options (method, dt, steps, precision, tolerances, "
                "guard, --every, --out): resume with the command line that made it");
  }
  return {command, fingerprint, j["fields"]};
}

std::uint64_t exact(double value) { return std::bit_cast<std::uint64_t>(value); }
double exact(std::uint64_t bits) { return std::bit_cast<double>(bits); }

std::string fingerprint_of(const std::string& scene_path, const std::string& options) {
  std::uint64_t hash = 14695981039346656037ull;
  const auto add = [&](std::span<const std::byte> bytes) {
    for (const std::byte b : bytes) hash = (hash ^ std::uint64_t(b)) * 1099511628211ull;
  };
  if (!scene_path.empty()) add(read_regular_file(scene_path, kMaxSceneBytes, "scene"));
  add(std::as_bytes(std::span(options.data(), options.size())));
  char text[20];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(hash));
  return text;
}

}  // namespace kinema::cli
