// No allocation inside step or advance, on either path, with TBB or serial jobs: a counting
// global operator new watches every allocation of the process.
#include <catch2/catch.hpp>

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <new>
#include <vector>

#include "support.hpp"

namespace {
std::atomic<long> g_allocations{0};
std::atomic<std::size_t> g_largest{0};  // the largest single allocation since last reset
}

// Every replaceable form, so that each allocation is counted and each pair matches.
namespace {
void* counted(std::size_t size, std::size_t alignment = alignof(std::max_align_t)) noexcept {
  ++g_allocations;
  for (std::size_t seen = g_largest.load(); size > seen && !g_largest.compare_exchange_weak(seen, size);) {
  }
  size = size == 0 ? 1 : size;
  if (alignment <= alignof(std::max_align_t)) return std::malloc(size);
  return std::aligned_alloc(alignment, (size + alignment - 1) / alignment * alignment);
}
void* counted_or_throw(std::size_t size, std::size_t alignment = alignof(std::max_align_t)) {
  if (void* p = counted(size, alignment)) return p;
  throw std::bad_alloc();
}
}  // namespace

void* operator new(std::size_t n) { return counted_or_throw(n); }
void* operator new[](std::size_t n) { return counted_or_throw(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return counted(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return counted(n); }
void* operator new(std::size_t n, std::align_val_t a) { return counted_or_throw(n, std::size_t(a)); }
void* operator new[](std::size_t n, std::align_val_t a) {
  return counted_or_throw(n, std::size_t(a));
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

using namespace kinema;

namespace {

template <class T>
long allocations_in_steps(const Method& method, ForceModel<T> forces, bool staged, bool tbb,
                          std::size_t count = 30000, FiniteGuard guard = FiniteGuard::off) {
  ParticleSet<T> bodies = test::cloud<T>(count);
  TbbJobSystem jobs(2);
  StepperOptions o = tbb ? StepperOptions{} : test::serial_options();
  if (tbb) o.jobs = &jobs, o.workers = WorkerChoice::all;
  o.force_staged = staged;
  o.guard = guard;
  Stepper<T> stepper(std::move(forces), method, o);
  stepper.step(bodies, T(0.01));  // first use: scratch and TBB's own lazy set-up
  const long before = g_allocations.load();
  stepper.advance(bodies, T(0.01), 10);
  for (int i = 0; i < 5; ++i) stepper.step(bodies, T(0.01));
  return g_allocations.load() - before;
}

// A user callback and a pairwise coupled term, so the staged path does all it can.
template <class T>
ForceModel<T> with_callback(ForceModel<T> f) {
  f.add([](const ParticleBlock<T>& b) {
    for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += T(0.1) * b.px[i];
  });
  return f;
}

// N-body gravity and a chain of springs through every body.
template <class T>
ForceModel<T> coupled(ForceModel<T> f, std::uint32_t bodies) {
  f.add(NBody{1e-3, 0.1});
  Springs chain;
  for (std::uint32_t i = 1; i < bodies; ++i) chain.pairs.push_back({i - 1, i, 0.5, 2, 0.1});
  f.add(chain);
  return f;
}

}  // namespace

TEST_CASE("steps with coupled terms allocate nothing", "[allocation]") {
  for (bool tbb : {false, true}) {
    for (const Method* m : {&euler, &rk4, &velocity_verlet}) {
      INFO(m->name << (tbb ? " on tbb" : " serial"));
      CHECK(allocations_in_steps<float>(*m, coupled(test::all_local_terms<float>(), 3000), false, tbb, 3000) == 0);
    }
  }
}

TEST_CASE("implicit steps allocate nothing after the first", "[allocation][implicit]") {
  for (bool tbb : {false, true}) {
    for (const Method* m : implicit_methods) {
      INFO(m->name << (tbb ? " on tbb" : " serial"));
      CHECK(allocations_in_steps<float>(*m, coupled(with_callback(test::all_local_terms<float>()), 3000), false, tbb,
                                        3000) == 0);
      CHECK(allocations_in_steps<double>(*m, coupled(test::all_local_terms<double>(), 3000), false, tbb, 3000) == 0);
    }
  }
}

TEST_CASE("implicit steps of a smaller set after a larger one allocate nothing", "[allocation][implicit]") {
  // A chain of 3000 bodies (multigrid) stepped on a set of 3100, then on one of 3000.
  Springs chain;
  for (std::uint32_t i = 1; i < 3000; ++i) chain.pairs.push_back({i - 1, i, 0.5, 2, 0.1});
  ForceModel<float> forces;
  forces.add(chain);
  Stepper<float> stepper(forces, implicit_euler, test::serial_options());
  ParticleSet<float> larger = test::cloud<float>(3100), smaller = test::cloud<float>(3000);
  stepper.step(larger, 0.01f);
  const long before = g_allocations.load();
  stepper.step(smaller, 0.01f);
  stepper.step(larger, 0.01f);
  CHECK(g_allocations.load() - before == 0);
  CHECK(stepper.implicit_stats().solves == 3);
}

TEST_CASE("step and advance allocate nothing", "[allocation]") {
  for (bool tbb : {false, true}) {
    for (const Method* m : builtin_methods) {
      INFO(m->name << (tbb ? " on tbb" : " serial"));
      CHECK(allocations_in_steps<float>(*m, test::all_local_terms<float>(), false, tbb) == 0);
      CHECK(allocations_in_steps<double>(*m, test::all_local_terms<double>(), true, tbb) == 0);
      CHECK(allocations_in_steps<float>(*m, with_callback(test::all_local_terms<float>()), false,
                                        tbb) == 0);
    }
  }
}

TEST_CASE("guarded steps allocate nothing after the first", "[allocation]") {
  for (bool tbb : {false, true}) {
    for (FiniteGuard guard : {FiniteGuard::check, FiniteGuard::clamp}) {
      INFO((guard == FiniteGuard::check ? "check" : "clamp") << (tbb ? " on tbb" : " serial"));
      CHECK(allocations_in_steps<float>(rk4, test::all_local_terms<float>(), false, tbb, 30000, guard) == 0);
      CHECK(allocations_in_steps<double>(euler, with_callback(test::all_local_terms<double>()), true,
                                         tbb, 30000, guard) == 0);
    }
  }
}

TEST_CASE("applied forces and rigid callbacks allocate nothing in steps", "[allocation]") {
  for (bool tbb : {false, true}) {
    TbbJobSystem jobs(2);
    StepperOptions o = tbb ? StepperOptions{} : test::serial_options();
    if (tbb) o.jobs = &jobs, o.workers = WorkerChoice::all;
    ParticleSet<float> particles = test::cloud<float>(20000);
    particles.keep_forces(true);
    for (std::size_t i = 0; i < particles.size(); i += 3) particles.apply_force(i, {1, 2, 3});
    RigidBodySet<float> rigid;
    for (std::size_t i = 0; i < 5000; ++i) rigid.add({{float(i % 9), 0, 0}, {}, {1, 0, 0.1f, 0}, {0.2f, 0, 0}, 1, {1, 2, 3}});
    rigid.keep_forces(true);
    rigid.apply_torque(7, {0, 1, 0});
    ForceModel<float> f = with_callback(test::all_local_terms<float>());
    f.add([](const RigidBlock<float>& b) {
      for (std::size_t i = 0; i < b.count; ++i) b.tz[i] -= 0.1f * b.wz[i];
    });
    for (const Method* m : {&rk4, &velocity_verlet}) {
      INFO(m->name << (tbb ? " on tbb" : " serial"));
      Stepper<float> sp(test::all_local_terms<float>(), *m, o), sr(f, *m, o), sc(f, *m, o);
      sp.step(particles, 0.01f), sr.step(rigid, 0.01f), sc.step(particles, 0.01f);
      const long before = g_allocations.load();
      sp.advance(particles, 0.01f, 5), sr.advance(rigid, 0.01f, 5), sc.advance(particles, 0.01f, 5);
      sp.step(particles, 0.01f), sr.step(rigid, 0.01f), sc.step(particles, 0.01f);
      CHECK(g_allocations.load() - before == 0);
    }
  }
}

TEST_CASE("applying forces and torques and impulses allocates nothing once the arrays are there", "[allocation]") {
  // A game applies them every frame: the per-frame calls must not allocate.
  ParticleSet<float> particles = test::cloud<float>(64);
  RigidBodySet<double> rigid;
  for (int i = 0; i < 64; ++i) rigid.add({{double(i), 0, 0}, {}, {1, 0, 0, 0}, {}, 1, {1, 2, 3}});
  particles.apply_force(0, {1, 0, 0}), rigid.apply_force(0, {1, 0, 0}), rigid.apply_torque(0, {0, 1, 0});
  const long before = g_allocations.load();
  for (std::size_t i = 0; i < 64; ++i) {
    particles.apply_force(i, {1, 2, 3});
    particles.apply_impulse(i, {0, 0.1f, 0});
    rigid.apply_force(i, {1, 2, 3});
    rigid.apply_torque(i, {0, 0, 1});
    rigid.apply_force_at(i, {0, 1, 0}, {double(i) + 1, 0, 0});
    rigid.apply_impulse(i, {0.1, 0, 0});
    rigid.apply_impulse_at(i, {0, 0.1, 0}, {double(i), 1, 0});
    rigid.apply_angular_impulse(i, {0, 0, 0.1});
  }
  CHECK(g_allocations.load() - before == 0);
}

TEST_CASE("rigid bodies on springs allocate nothing in steps or error-controlled steps", "[allocation]") {
  for (bool tbb : {false, true}) {
    TbbJobSystem jobs(2);
    StepperOptions o = tbb ? StepperOptions{} : test::serial_options();
    if (tbb) o.jobs = &jobs, o.workers = WorkerChoice::all;
    RigidBodySet<double> rigid;
    BodySprings chain;
    for (std::size_t i = 0; i < 3000; ++i) {
      rigid.add({{double(i % 50), 0, double(i / 50)}, {}, {1, 0, 0.1, 0}, {0.2, 0, 0}, 1, {1, 2, 3}});
      if (i > 0) chain.springs.push_back({std::uint32_t(i - 1), std::uint32_t(i), {0.1, 0, 0}, {-0.1, 0, 0}, 1, 5, 0.1});
    }
    ForceModel<double> f;
    f.add(Gravity{}).add(PointSpring{{0, 0.2, 0}, {0, 3, 0}, 0.5, 0}).add(chain);
    for (const Method* m : {&rk4, &velocity_verlet}) {
      INFO(m->name << (tbb ? " on tbb" : " serial"));
      Stepper<double> s(f, *m, o);
      s.step(rigid, 0.01);
      const long before = g_allocations.load();
      s.advance(rigid, 0.01, 3);
      s.step(rigid, 0.01);
      CHECK(g_allocations.load() - before == 0);
    }
    Stepper<double> adaptive(f, dopri5, o);
    adaptive.advance_to(rigid, 0.05, {});
    const long before = g_allocations.load();
    adaptive.advance_to(rigid, 0.1, {});
    CHECK(g_allocations.load() - before == 0);
  }
}

TEST_CASE("a hostile checkpoint is refused before anything past its own size is allocated", "[allocation][checkpoint]") {
  // A small checkpoint whose body count says 2^40 (its checksums made right again): the reader
  // compares every count with the data's length before it allocates for bodies.
  ParticleSet<float> b = test::cloud<float>(3);
  Stepper<float> s(test::all_local_terms<float>(), rk4, test::serial_options());
  CheckpointWriter out;
  out.add(b, s);
  std::vector<std::byte> data = out.bytes();
  const std::uint64_t huge = std::uint64_t(1) << 40;
  std::memcpy(data.data() + kCheckpointHeaderBytes + 8, &huge, sizeof huge);
  const std::size_t record_crc = kCheckpointRecordBytes - 4;
  const std::uint32_t crc = crc32c({data.data() + kCheckpointHeaderBytes, record_crc});
  std::memcpy(data.data() + kCheckpointHeaderBytes + record_crc, &crc, sizeof crc);
  const std::uint32_t whole = crc32c({data.data(), data.size() - 4});
  std::memcpy(data.data() + data.size() - 4, &whole, sizeof whole);
  const std::size_t size = data.size();
  g_largest = 0;
  CHECK_THROWS_WITH(CheckpointReader(std::move(data)), Catch::Contains("more than its"));
  CHECK(g_largest.load() <= size);
}
