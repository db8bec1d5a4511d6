#pragma once
// The benchmark problem every suite shares: N particles under gravity, linear drag and a
// spring to the origin, the same bodies for kinema, the naive baseline and Odeint.

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <map>
#include <mutex>
#include <vector>

#include "kinema/scenes.hpp"

namespace kinema::bench {

inline constexpr double kGravity = -9.81, kDrag = 0.5, kSpring = 2.0, kDt = 1.0 / 60;

inline Scene bench_scene(std::size_t count) {
  Scene s;
  s.generate = GenerateSpec{count, 7, {-10, -10, -10}, {10, 10, 10}, {-1, -1, -1}, {1, 1, 1}, 1};
  s.forces = {Gravity{{0, kGravity, 0}}, LinearDrag{kDrag}, Spring{{0, 0, 0}, kSpring, 0}};
  return s;
}

// The same scene as rigid bodies: orientation and angular momentum added, and angular drag.
inline Scene rigid_bench_scene(std::size_t count) {
  Scene s = bench_scene(count);
  s.generate->rigid = true;
  s.generate->inertia = {0.5, 0.8, 1.1};
  s.generate->angular_velocity_min = {-3, -3, -3};
  s.generate->angular_velocity_max = {3, 3, 3};
  s.forces.push_back(AngularDrag{0.05});
  return s;
}

// State bytes a particle step reads and writes: 7 arrays in, 6 out.
template <class T>
constexpr double particle_step_bytes() {
  return 13.0 * sizeof(T);
}

// State bytes per rigid step: 17 arrays in (centre 7, q 4, L 3, inverse inertia 3), 13 out.
template <class T>
constexpr double rigid_step_bytes() {
  return 30.0 * sizeof(T);
}

// Counters every suite reports, so ratios can be read across rows.
inline void report_body_steps(benchmark::State& state, double body_steps_per_iteration,
                              double bytes_per_body_step) {
  using benchmark::Counter;
  const double total = body_steps_per_iteration * double(state.iterations());
  state.counters["ns_per_body_step"] = Counter(total * 1e-9, Counter::kIsRate | Counter::kInvert);
  state.counters["body_steps_per_s"] = Counter(total, Counter::kIsRate);
  state.counters["GB_per_s"] = Counter(total * bytes_per_body_step * 1e-9, Counter::kIsRate);
}

// Bodies made by make(count) once per process and count (4M bodies take a while).
template <class Set, class Make>
const Set& cached(std::size_t count, Make make) {
  static std::map<std::size_t, Set> cache;
  static std::mutex mutex;
  std::lock_guard lock(mutex);
  auto [it, fresh] = cache.try_emplace(count);
  if (fresh) it->second = make(count);
  return it->second;
}

template <class T>
const ParticleSet<T>& cached_particles(std::size_t count) {
  return cached<ParticleSet<T>>(count, [](std::size_t n) { return make_particles<T>(bench_scene(n)); });
}

// Puts the initial state back without allocating. Benchmarks do so every few thousand
// steps: drag would otherwise decay velocities into subnormals over a long run, which some
// CPUs process far more slowly (the cost of the copy is spread over those steps).
template <class T>
void restore(ParticleSet<T>& bodies, const ParticleSet<T>& initial) {
  T* dst[] = {bodies.px(), bodies.py(), bodies.pz(), bodies.vx(), bodies.vy(), bodies.vz()};
  const T* src[] = {initial.px(), initial.py(), initial.pz(), initial.vx(), initial.vy(), initial.vz()};
  for (int a = 0; a < 6; ++a) std::memcpy(dst[a], src[a], bodies.padded_size() * sizeof(T));
}

inline constexpr std::int64_t kRestoreEvery = 4096;

// The middle value (the upper one of an even count); 0 for none.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// The job system a case runs on: the calling thread alone for one thread, else oneTBB.
struct CaseJobs {
  explicit CaseJobs(unsigned threads) : tbb(threads), threads(threads) {}
  JobSystem* get() { return threads == 1 ? static_cast<JobSystem*>(&serial) : &tbb; }
  TbbJobSystem tbb;
  SerialJobSystem serial;
  unsigned threads;
};

// Fails the run (visible in the output) when a benchmark left a non-finite state behind.
template <class T>
void require_finite(benchmark::State& state, const ParticleSet<T>& bodies) {
  if (!all_finite(bodies)) state.SkipWithError("state is not finite after the run");
}

}  // namespace kinema::bench
