#pragma once
// One kinema_bench run read from Google Benchmark's JSON: each run's counters (median, CV and
// best repetition) and the context the header line names.
#include <map>
#include <optional>
#include <string>

#include "format.hpp"

namespace kinema::bench::report {

// run name -> counter -> figure
using Runs = std::map<std::string, std::map<std::string, Figure>>;

struct Context {
  std::string cpu_model, cpu_family, date;
  int num_cpus = 0;
  std::string isa;                // the ISA the kernels used (the suites' names carry it)
  std::map<int, double> caches;   // data cache bytes per level
};

class Results {
 public:
  Results(Runs runs, Context context) : runs_(std::move(runs)), context_(std::move(context)) {}

  // A counter of a run, when the run has it with a non-zero median (a figure to divide by).
  std::optional<Figure> find(const std::string& run, const char* counter) const;
  // A counter's median as it is, 0 included (a count, a worker number).
  std::optional<double> count(const std::string& run, const char* counter) const;
  // A counter's median as a cell, "-" when find() has nothing.
  std::string value(const std::string& run, const char* counter, const char* format = "%.1f") const;

  bool empty() const { return runs_.empty(); }
  const std::string& isa() const { return context_.isa; }
  const Context& context() const { return context_; }

 private:
  Runs runs_;
  Context context_;
};

// Reads the JSON at `path`; throws std::exception with a message on failure.
Results load_results(const char* path);

}  // namespace kinema::bench::report
