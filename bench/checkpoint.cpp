// Checkpoints of 1M bodies beside a plain write of the same bytes to the same disk, same run:
// the checkpoint's own cost is its checksums, its temporary file and rename, and (read) the
// copy into a new set. Both writes are synced (a checkpoint that a crash can lose is no
// checkpoint); the unsynced plain write shows what the sync itself costs here.
#include <benchmark/benchmark.h>

#include <fcntl.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

constexpr std::size_t kBodies = std::size_t(1) << 20;

std::filesystem::path scratch_file(const char* name) {
  return std::filesystem::temp_directory_path() / (std::string("kinema-bench-") + name + "-" + std::to_string(::getpid()));
}

template <class T>
struct Saved {
  ParticleSet<T> bodies = cached_particles<T>(kBodies);
  Stepper<T> stepper{make_forces<T>(bench_scene(kBodies)), rk4, on_calling_thread()};
  std::vector<std::byte> bytes() const {
    CheckpointWriter out;
    out.add(bodies, stepper);
    return out.bytes();
  }
};

void report_bytes(benchmark::State& state, std::size_t bytes) {
  state.SetBytesProcessed(std::int64_t(bytes) * state.iterations());
  state.counters["MB"] = double(bytes) * 1e-6;
}

template <class T>
void checkpoint_write(benchmark::State& state) {
  const Saved<T> saved;
  const auto path = scratch_file("checkpoint");
  for (auto _ : state) {
    CheckpointWriter out;
    out.add(saved.bodies, saved.stepper);
    out.save(path);
  }
  report_bytes(state, std::filesystem::file_size(path));
  std::filesystem::remove(path);
}

// The checkpoint's bytes with open, write, fsync (when `sync`), close: nothing more.
template <class T>
void plain_write(benchmark::State& state, bool sync) {
  const std::vector<std::byte> bytes = Saved<T>().bytes();
  const auto path = scratch_file("plain");
  for (auto _ : state) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const bool written = ::write(fd, bytes.data(), bytes.size()) == ssize_t(bytes.size());
    if (!written || (sync && ::fsync(fd) != 0)) state.SkipWithError("the plain write failed");
    ::close(fd);
  }
  report_bytes(state, bytes.size());
  std::filesystem::remove(path);
}

template <class T>
void checkpoint_read(benchmark::State& state) {
  Saved<T> saved;
  const auto path = scratch_file("checkpoint-read");
  write_whole_file(path, saved.bytes(), "checkpoint");
  for (auto _ : state) {
    const CheckpointReader in = CheckpointReader::load(path);
    in.restore(0, saved.bodies, saved.stepper);
    benchmark::DoNotOptimize(saved.bodies.px());
  }
  report_bytes(state, std::filesystem::file_size(path));
  std::filesystem::remove(path);
}

template <class T>
void plain_read(benchmark::State& state) {
  const auto path = scratch_file("plain-read");
  write_whole_file(path, Saved<T>().bytes(), "checkpoint");
  for (auto _ : state) {
    std::vector<std::byte> data = read_regular_file(path, std::size_t(1) << 40, "file");
    benchmark::DoNotOptimize(data.data());
  }
  report_bytes(state, std::filesystem::file_size(path));
  std::filesystem::remove(path);
}

template <class T>
void register_type(const std::string& type) {
  const std::string size = "/" + std::to_string(kBodies);
  benchmark::RegisterBenchmark(("checkpoint/write/" + type + size).c_str(), checkpoint_write<T>)->UseRealTime()->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark(("checkpoint/plain_write/" + type + size).c_str(), plain_write<T>, true)->UseRealTime()->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark(("checkpoint/plain_write_unsynced/" + type + size).c_str(), plain_write<T>, false)
      ->UseRealTime()->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark(("checkpoint/read/" + type + size).c_str(), checkpoint_read<T>)->UseRealTime()->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark(("checkpoint/plain_read/" + type + size).c_str(), plain_read<T>)->UseRealTime()->Unit(benchmark::kMillisecond);
}

const bool registered = [] {
  register_type<float>("float");
  register_type<double>("double");
  return true;
}();

}  // namespace
}  // namespace kinema::bench
