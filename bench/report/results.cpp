#include "results.hpp"

#include <fstream>
#include <iterator>
#include <regex>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace kinema::bench::report {
namespace {

using json = nlohmann::json;

// Google Benchmark writes a counter's undefined statistics (the cv of a counter that is 0 in
// every repetition) as NaN or inf, which JSON has no word for: read those as null.
json parse_benchmark_json(const char* path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open the file");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  static const std::regex undefined(R"(:\s*-?(NaN|nan|inf|Infinity)\b)");
  return json::parse(std::regex_replace(text, undefined, ": null"));
}

// The median, cv and max aggregates (or a plain run's values); the others are skipped.
bool wanted(const std::string& run_type, const std::string& aggregate) {
  return run_type != "aggregate" || aggregate == "median" || aggregate == "cv" || aggregate == "max";
}

void store(Figure& f, const std::string& aggregate, double value) {
  if (aggregate == "cv") {
    f.cv = value;
  } else if (aggregate == "max") {
    f.max = value;
  } else if (aggregate == "median" || aggregate.empty()) {
    f.median = value;
  }
}

Runs load_runs(const json& doc) {
  Runs runs;
  for (const json& b : doc.at("benchmarks")) {
    const std::string run = b.value("run_name", b.value("name", ""));
    const std::string aggregate = b.value("aggregate_name", "");
    if (!wanted(b.value("run_type", ""), aggregate)) continue;
    if (b.contains("error_occurred") && b["error_occurred"].get<bool>()) continue;
    for (const auto& [key, value] : b.items()) {
      if (value.is_number()) store(runs[run][key], aggregate, value.get<double>());
    }
  }
  return runs;
}

// Data cache sizes per level from the run's context (Google Benchmark reads them).
std::map<int, double> data_caches(const json& context) {
  std::map<int, double> sizes;
  for (const json& c : context.value("caches", json::array())) {
    if (c.value("type", "") != "Instruction") sizes[c.value("level", 0)] = c.value("size", 0.0);
  }
  return sizes;
}

Context load_context(const json& context) {
  Context c;
  c.cpu_model = context.value("cpu_model", "?");
  c.cpu_family = context.value("cpu_family", "?");
  c.date = context.value("date", "?");
  c.num_cpus = context.value("num_cpus", 0);
  c.isa = context.value("kinema_best_isa", "avx512");
  c.caches = data_caches(context);
  return c;
}

}  // namespace

std::optional<Figure> Results::find(const std::string& run, const char* counter) const {
  const auto r = runs_.find(run);
  if (r == runs_.end()) return std::nullopt;
  const auto c = r->second.find(counter);
  if (c == r->second.end() || c->second.median == 0) return std::nullopt;
  return c->second;
}

std::optional<double> Results::count(const std::string& run, const char* counter) const {
  const auto r = runs_.find(run);
  if (r == runs_.end()) return std::nullopt;
  const auto c = r->second.find(counter);
  if (c == r->second.end()) return std::nullopt;
  return c->second.median;
}

std::string Results::value(const std::string& run, const char* counter, const char* format) const {
  return cell(median(find(run, counter)), format);
}

Results load_results(const char* path) {
  const json doc = parse_benchmark_json(path);
  return Results(load_runs(doc), load_context(doc.at("context")));
}

}  // namespace kinema::bench::report
