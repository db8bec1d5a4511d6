#include "run_checkpoint.hpp"

#include <bit>
#include <cstdio>
#include <filesystem>

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
    const char* options = command == "stress" ? "bodies, seed, method, dt, steps, seconds, precision, guard and speeds"
                                              : "method, dt, steps, precision, tolerances, --every, --out, "
                                                "--relaxed-fma, the --implicit-* options";
    throw Error(where + "taken under another scene or other options (" + options +
                "): resume with the command line that made it");
  }
  return {command, fingerprint, j["fields"]};
}

namespace {

// The same file: one existing file under two names, or two names of one path yet to be made.
// Devices are not files to clobber (--out /dev/null --summary /dev/null is fine).
bool same_file(const std::string& a, const std::string& b) {
  std::error_code error;
  if (std::filesystem::exists(a, error) && !std::filesystem::is_regular_file(a, error)) return false;
  if (std::filesystem::equivalent(a, b, error)) return true;
  // Absolute first: a relative path none of whose parts exists yet (y.csv) stays relative
  // under weakly_canonical, and would differ from ./y.csv or $PWD/y.csv.
  const auto absolute_a = std::filesystem::absolute(a, error);
  if (error) return false;
  const auto absolute_b = std::filesystem::absolute(b, error);
  if (error) return false;
  const auto canonical_a = std::filesystem::weakly_canonical(absolute_a, error);
  if (error) return false;
  const auto canonical_b = std::filesystem::weakly_canonical(absolute_b, error);
  return !error && canonical_a == canonical_b;
}

}  // namespace

void check_distinct(const std::vector<NamedPath>& inputs, const std::vector<NamedPath>& outputs) {
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    if (outputs[i].path.empty()) continue;
    const auto clash = [&](const NamedPath& other, const char* what) {
      if (other.path.empty() || !same_file(outputs[i].path, other.path)) return;
      throw Error(outputs[i].option + " " + printable(outputs[i].path) + " is the " + what + " " + other.option +
                  " names: one would overwrite the other");
    };
    for (const NamedPath& input : inputs) clash(input, "input");
    for (std::size_t j = i + 1; j < outputs.size(); ++j) clash(outputs[j], "file");
  }
}

void check_apart(const std::string& what, const std::string& path, const std::vector<NamedPath>& named) {
  for (const NamedPath& other : named) {
    if (other.path.empty() || !same_file(path, other.path)) continue;
    throw Error(what + " " + printable(path) + ", the file " + other.option + ": one would overwrite the other");
  }
}

std::uint64_t exact(double value) { return std::bit_cast<std::uint64_t>(value); }
double exact(std::uint64_t bits) { return std::bit_cast<double>(bits); }

std::string fingerprint_of(const std::string& scene_path, const std::string& options) {
  std::uint32_t crc = 0;
  if (!scene_path.empty()) crc = crc32c(read_regular_file(scene_path, kMaxSceneBytes, "scene"));
  return crc_text(crc32c(std::as_bytes(std::span(options.data(), options.size())), crc));
}

std::string crc_text(std::uint32_t crc) {
  char text[12];
  std::snprintf(text, sizeof text, "%08x", unsigned(crc));
  return text;
}

}  // namespace kinema::cli
