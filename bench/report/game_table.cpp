// Forces from the game: the fused step beside the same bench scene with applied forces, with
// per-body parameters, with a callback (the block path) and with a coupled term (the staged path), and the same for
// rigid bodies, each against the fused row and the state stream of the same run.
#include <cstdio>
#include <string>

#include "format.hpp"
#include "machine_limits.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

constexpr long kBodies = 100000;

struct GameRow {
  const char* variant;  // as the benchmark names it
  const char* what;
  const char* base;     // the row it is compared with
  double bytes;         // state bytes per body-step (read + written)
};

void print_row(const Results& results, Noise& noise, const GameRow& row, std::optional<Figure> stream) {
  const std::string at = "/rk4/float/" + results.isa() + "/100000/real_time";
  const auto f = results.find("game/" + std::string(row.variant) + at, "ns_per_body_step");
  if (!f) return;
  noise.add(f->cv);
  const auto base = results.find("game/" + std::string(row.base) + at, "ns_per_body_step");
  // The time the state's own traffic takes at the stream's speed: bytes / (GB/s) = ns.
  const std::optional<double> limit = stream ? std::optional<double>(row.bytes / stream->median) : std::nullopt;
  std::printf("%-16s %-44s %8.3f %8s %8s\n", row.variant, row.what, f->median, cell(ratio(f, base), "%.2fx").c_str(),
              cell(limit ? std::optional<double>(f->median / *limit) : std::nullopt, "%.1fx").c_str());
}

}  // namespace

void print_game_table(const Results& results, Noise& noise) {
  if (!results.find("game/fused/rk4/float/" + results.isa() + "/100000/real_time", "ns_per_body_step")) return;
  std::printf("\nForces from the game, rk4, float, N = %ld, 1 thread, %s, advance of 20 steps per call: ns per "
              "body-step, times the fused row, times the state stream's time for the state's bytes\n",
              kBodies, results.isa().c_str());
  std::printf("%-16s %-44s %8s %8s %8s\n", "row", "what", "ns", "/fused", "/stream");
  const auto stream = state_stream(results, "float", kBodies, 1);
  const GameRow rows[] = {
      {"fused", "gravity, drag, spring: built-in terms", "fused", 52},
      {"applied", "the same and a force applied to every body", "fused", 64},
      {"parameters", "a gravity factor and damping on every body", "fused", 60},
      {"callback", "gravity in a one-line callback (block path)", "fused", 52},
      {"callback-divide", "the same, g / inv_mass instead of g * mass", "fused", 52},
      {"callback-empty", "built-in gravity, a callback adding nothing", "fused", 52},
      {"staged", "a coupled term that adds nothing (staged)", "fused", 52},
      {"springs", "chains of 64 joined by spring pairs (staged)", "fused", 52},
      {"rigid-fused", "rigid bodies, angular drag built in", "rigid-fused", 120},
      {"rigid-applied", "and a force and torque on every body", "rigid-fused", 144},
      {"rigid-parameters", "and gravity factor, damping, angular damping", "rigid-fused", 132},
      {"rigid-callback", "angular drag in a one-line callback", "rigid-fused", 120},
      {"rigid-springs", "chains of 64 joined by body springs (staged)", "rigid-fused", 120},
  };
  for (const GameRow& row : rows) print_row(results, noise, row, stream);
}

}  // namespace kinema::bench::report
