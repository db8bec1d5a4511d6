// Checkpoints of 1M bodies against a plain write (and read) of the same bytes to the same disk,
// same run: the speed of each as a fraction of the plain one's.
#include <cstdio>
#include <string>

#include "format.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

struct CheckpointRow {
  const char* run;    // as the benchmark names it, after "checkpoint/"
  const char* what;
  const char* plain;  // the row it is compared with
};

void print_row(const Results& results, Noise& noise, const CheckpointRow& row, const std::string& at) {
  const auto f = results.find("checkpoint/" + std::string(row.run) + at, "real_time");
  if (!f) return;
  noise.add(f->cv);
  const auto plain = results.find("checkpoint/" + std::string(row.plain) + at, "real_time");
  const auto rate = results.find("checkpoint/" + std::string(row.run) + at, "bytes_per_second");
  // Speed against the plain row's: its time over ours.
  const std::optional<double> speed = plain ? std::optional<double>(plain->median / f->median) : std::nullopt;
  std::printf("%-24s %-46s %8.1f %8s %8s\n", row.run, row.what, f->median,
              cell(rate ? std::optional<double>(rate->median * 1e-9) : std::nullopt, "%.2f").c_str(),
              cell(speed, "%.2fx").c_str());
}

}  // namespace

void print_checkpoint_table(const Results& results, Noise& noise) {
  const CheckpointRow rows[] = {
      {"write", "save to a file: CRC-32C, temporary, sync, rename", "plain_write"},
      {"plain_write", "the same bytes: write and fsync", "plain_write"},
      {"plain_write_unsynced", "the same bytes: write alone", "plain_write_unsynced"},
      {"write", "save, against the unsynced write", "plain_write_unsynced"},
      {"read", "load, check, restore into a new set", "plain_read"},
      {"plain_read", "the same file read into memory", "plain_read"},
  };
  for (const char* type : {"float", "double"}) {
    const std::string at = "/" + std::string(type) + "/1048576/real_time";
    if (!results.find("checkpoint/write" + at, "real_time")) continue;
    std::printf("\nCheckpoints, %s, 1048576 particles, one file on the temporary directory's disk: ms, GB/s, and "
                "speed as a fraction of the plain write's (read's)\n", type);
    std::printf("%-24s %-46s %8s %8s %8s\n", "row", "what", "ms", "GB/s", "speed");
    for (const CheckpointRow& row : rows) print_row(results, noise, row, at);
  }
}

}  // namespace kinema::bench::report
