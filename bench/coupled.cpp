// Coupled terms at the machine's limits: N-body gravity (interactions per second and the
// fraction of the FMA peak, against a plain scalar double loop) and a 512 x 512 cloth's
// spring network (ns per spring, bytes moved against in-place streaming).
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>
#include <vector>

#include "bench_scene.hpp"
#include "forces/coupled_forces.hpp"
#include "kernels/kernels.hpp"

namespace kinema::bench {
namespace {

// The N-body literature's count per interaction (a subtraction per axis, the squared
// distance, an inverse square root counted as several, the mass factor, three FMAs).
constexpr double kFlopsPerInteraction = 20;

Scene cluster_scene(std::size_t n, bool fast = false) {
  Scene s;
  s.generate = GenerateSpec{};
  s.generate->count = n;
  s.generate->seed = 3;
  s.generate->mass = 1.0 / double(n);
  s.generate->plummer_radius = 1;
  s.nbody = NBody{1, 0.01, fast};
  return s;
}

void report_interactions(benchmark::State& state, double per_iteration) {
  using benchmark::Counter;
  const double total = per_iteration * double(state.iterations());
  state.counters["interactions_per_s"] = Counter(total, Counter::kIsRate);
  state.counters["GFLOP_per_s"] = Counter(total * kFlopsPerInteraction * 1e-9, Counter::kIsRate);
}

// One Euler step: one gravity evaluation (n^2 interactions) plus O(n) passes. Fast: the
// term's fast inverse cube (float).
template <class T>
void nbody_step(benchmark::State& state, Isa isa, unsigned threads, bool fast) {
  const auto n = std::size_t(state.range(0));
  const Scene scene = cluster_scene(n, fast);
  ParticleSet<T> bodies = make_particles<T>(scene);
  CaseJobs jobs(threads);
  StepperOptions o;
  o.isa = isa;
  o.jobs = jobs.get();
  o.workers = WorkerChoice::all;  // n threads, not the measured choice (frame_loop times that)
  Stepper<T> stepper(make_forces<T>(scene), euler, o);
  stepper.step(bodies, T(1e-6));
  for (auto _ : state) {
    stepper.step(bodies, T(1e-6));
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  report_interactions(state, double(n) * double(n));
  state.SetLabel(std::string(isa_name(stepper.isa())));
}

// The plain loop a newcomer writes: double, scalar, one pair at a time.
void nbody_scalar_baseline(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  const ParticleSet<double> b = make_particles<double>(cluster_scene(n));
  std::vector<double> ax(n), ay(n), az(n), mass(n);
  for (std::size_t i = 0; i < n; ++i) mass[i] = 1 / b.inv_mass()[i];
  const double eps2 = 1e-4;
  for (auto _ : state) {
    for (std::size_t i = 0; i < n; ++i) {
      double sx = 0, sy = 0, sz = 0;
      for (std::size_t j = 0; j < n; ++j) {
        if (j == i) continue;
        const double dx = b.px()[j] - b.px()[i], dy = b.py()[j] - b.py()[i], dz = b.pz()[j] - b.pz()[i];
        const double r2 = dx * dx + dy * dy + dz * dz + eps2;
        const double s = mass[j] / (r2 * std::sqrt(r2));
        sx += s * dx, sy += s * dy, sz += s * dz;
      }
      ax[i] = sx, ay[i] = sy, az[i] = sz;
    }
    benchmark::DoNotOptimize(ax.data());
    benchmark::DoNotOptimize(ay.data());
    benchmark::DoNotOptimize(az.data());
  }
  report_interactions(state, double(n) * double(n));
}

// A side x side cloth: structural springs to the right and below, shear springs on both
// diagonals of each cell; the bodies slightly jittered.
struct Cloth {
  ParticleSet<float> bodies;
  ForceModel<float> forces;
};

const Cloth& cloth(std::uint32_t side) {
  return cached<Cloth>(side, [](std::size_t s) {
    Scene scene;
    scene.springs.emplace_back();
    for (std::size_t r = 0; r < s; ++r) {
      for (std::size_t c = 0; c < s; ++c) {
        const double jitter = 1e-3 * double((r * 7 + c * 13) % 5);
        scene.particles.push_back({{double(c) * 0.01 + jitter, 0, double(r) * 0.01}, {}, 0.001, false, {}, {}, {}});
        auto spring = [&](std::size_t a, std::size_t b, double rest) {
          scene.springs[0].pairs.push_back({std::uint32_t(a), std::uint32_t(b), rest, 100, 0.01});
        };
        const std::size_t i = r * s + c;
        if (c + 1 < s) spring(i, i + 1, 0.01);
        if (r + 1 < s) spring(i, i + s, 0.01);
        if (r + 1 < s && c + 1 < s) spring(i, i + s + 1, 0.01 * std::sqrt(2.0)), spring(i + 1, i + s, 0.01 * std::sqrt(2.0));
      }
    }
    return Cloth{make_particles<float>(scene), make_forces<float>(scene)};
  });
}

// The spring kernel alone over the whole cloth, one thread: every body's springs once.
// Bytes: each body's position and velocity read, its force read and written, and per slot
// lane the three parameters, plus the index where the slot is gathered.
void spring_kernel(benchmark::State& state, Isa isa) {
  const Cloth& c = cloth(std::uint32_t(state.range(0)));
  const CoupledForces<float> lowered = lower_coupled<float>(c.forces);
  const SpringNetwork<float>& net = lowered.springs;
  const std::size_t n = c.bodies.padded_size();
  std::array<AlignedArray<float>, 3> force{AlignedArray<float>(n), AlignedArray<float>(n), AlignedArray<float>(n)};
  const float* x[3] = {c.bodies.px(), c.bodies.py(), c.bodies.pz()};
  const float* v[3] = {c.bodies.vx(), c.bodies.vy(), c.bodies.vz()};
  float* f[3] = {force[0].data(), force[1].data(), force[2].data()};
  const kernels::SpringJob<float> job = net.job(x, v, f);
  const auto& table = kernels::kernel_table<float>(isa);
  for (auto _ : state) {
    table.springs(job, 0, n);
    benchmark::ClobberMemory();
  }
  double gathered = 0;
  for (std::int32_t code : net.contiguous) gathered += code == -1;
  const double entries = double(net.contiguous.size());
  const double bytes = double(c.bodies.size()) * 12 * sizeof(float) +
                       entries * double(kernels::kSpringSlice) * 3 * sizeof(float) +
                       gathered * double(kernels::kSpringSlice) * sizeof(std::int32_t) +
                       entries * sizeof(std::int32_t);
  using benchmark::Counter;
  const double springs = double(c.forces.springs().size()), it = double(state.iterations());
  state.counters["ns_per_spring"] = Counter(springs * it * 1e-9, Counter::kIsRate | Counter::kInvert);
  state.counters["GB_per_s"] = Counter(bytes * it * 1e-9, Counter::kIsRate);
  state.counters["gathered_fraction"] = gathered / entries;
  state.SetLabel(std::string(isa_name(table.isa)));
}

// A whole Euler step of the cloth (stage, springs, forces, finish) on 1 or 2 threads.
void cloth_step(benchmark::State& state, Isa isa, unsigned threads) {
  const Cloth& c = cloth(std::uint32_t(state.range(0)));
  ParticleSet<float> bodies = c.bodies;
  CaseJobs jobs(threads);
  StepperOptions o;
  o.isa = isa;
  o.jobs = jobs.get();
  o.workers = WorkerChoice::all;  // n threads, not the measured choice (frame_loop times that)
  Stepper<float> stepper(c.forces, euler, o);
  stepper.step(bodies, 1e-5f);
  for (auto _ : state) {
    stepper.step(bodies, 1e-5f);
    benchmark::ClobberMemory();
  }
  require_finite(state, bodies);
  using benchmark::Counter;
  const double springs = double(c.forces.springs().size()), it = double(state.iterations());
  state.counters["ns_per_spring"] = Counter(springs * it * 1e-9, Counter::kIsRate | Counter::kInvert);
}

void register_all() {
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    const std::string name(isa_name(isa));
    for (unsigned t : {1u, 2u}) {
      const std::string threads = "/threads:" + std::to_string(t);
      benchmark::RegisterBenchmark(("nbody/float/" + name + threads).c_str(), nbody_step<float>, isa, t, false)
          ->Arg(4096)->Arg(16384)->UseRealTime()->Unit(benchmark::kMillisecond);
      benchmark::RegisterBenchmark(("nbody/float-fast/" + name + threads).c_str(), nbody_step<float>, isa, t, true)
          ->Arg(4096)->Arg(16384)->UseRealTime()->Unit(benchmark::kMillisecond);
      benchmark::RegisterBenchmark(("nbody/double/" + name + threads).c_str(), nbody_step<double>, isa, t, false)
          ->Arg(4096)->Arg(16384)->UseRealTime()->Unit(benchmark::kMillisecond);
      benchmark::RegisterBenchmark(("cloth/float/" + name + threads).c_str(), cloth_step, isa, t)
          ->Arg(512)->UseRealTime()->Unit(benchmark::kMillisecond);
    }
    benchmark::RegisterBenchmark(("springs/float/" + name).c_str(), spring_kernel, isa)
        ->Arg(128)->Arg(512)->UseRealTime()->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("baseline/nbody_scalar_double", nbody_scalar_baseline)
      ->Arg(4096)->UseRealTime()->Unit(benchmark::kMillisecond);
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
