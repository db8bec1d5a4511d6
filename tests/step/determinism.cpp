// Bit-identical results: run to run, across thread counts and job systems, across
// instruction sets, and between the fused and the staged paths.
#include <catch2/catch.hpp>

#include <cmath>
#include <map>

#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

constexpr std::size_t kBodies = 20000;  // 20 blocks: enough to split across threads

template <class T>
std::uint64_t run_hash(const Method& method, const ForceModel<T>& forces, StepperOptions o,
                       std::size_t bodies = kBodies, int steps = 20) {
  ParticleSet<T> b = test::cloud<T>(bodies);
  Stepper<T> s(forces, method, o);
  s.advance(b, T(0.01), steps);
  REQUIRE(all_finite(b));
  return test::state_hash(b);
}

template <class T>
void check_thread_counts() {
  const ForceModel<T> f = test::all_local_terms<T>();
  for (const Method* m : builtin_methods) {
    INFO("method " << m->name);
    const std::uint64_t serial = run_hash(*m, f, test::serial_options());
    for (unsigned threads : {1u, 2u, 3u, 8u}) {
      TbbJobSystem tbb(threads);
      StepperOptions o;
      o.jobs = &tbb;
      o.workers = WorkerChoice::all;
      INFO("threads " << threads);
      CHECK(run_hash(*m, f, o) == serial);
    }
  }
}

template <class T>
void check_isas() {
  for (bool quadratic : {false, true}) {
    for (bool central : {false, true}) {
      const ForceModel<T> f = test::all_local_terms<T>(quadratic, central);
      for (const Method* m : builtin_methods) {
        const std::uint64_t scalar = run_hash(*m, f, test::serial_options(Isa::scalar), 2000);
        for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
          if (!isa_available(isa)) continue;
          INFO(m->name << " on " << isa_name(isa) << " quadratic " << quadratic << " central "
                       << central);
          CHECK(run_hash(*m, f, test::serial_options(isa), 2000) == scalar);
        }
      }
    }
  }
}

}  // namespace

TEST_CASE("a step gives the same bits run after run", "[determinism]") {
  const ForceModel<float> f = test::all_local_terms<float>();
  for (const Method* m : builtin_methods) {
    CHECK(run_hash(*m, f, test::serial_options()) == run_hash(*m, f, test::serial_options()));
  }
}

TEST_CASE("results are bit-identical for 1, 2, 3 and 8 threads (float)", "[determinism]") {
  check_thread_counts<float>();
}

TEST_CASE("results are bit-identical for 1, 2, 3 and 8 threads (double)", "[determinism]") {
  check_thread_counts<double>();
}

TEST_CASE("every ISA computes the scalar path's bits (float)", "[determinism][isa]") {
  check_isas<float>();
}

TEST_CASE("every ISA computes the scalar path's bits (double)", "[determinism][isa]") {
  check_isas<double>();
}

TEST_CASE("fused and staged paths give the same bits", "[determinism]") {
  for (bool quadratic : {false, true}) {
    for (bool central : {false, true}) {
      const ForceModel<double> f = test::all_local_terms<double>(quadratic, central);
      for (const Method* m : builtin_methods) {
        StepperOptions staged = test::serial_options();
        staged.force_staged = true;
        INFO(m->name << " quadratic " << quadratic << " central " << central);
        CHECK(run_hash(*m, f, staged, 3000) == run_hash(*m, f, test::serial_options(), 3000));
      }
    }
  }
}

TEST_CASE("a host's own thread pool gives the serial bits", "[determinism][job_system]") {
  test::ThreadPool pool(3);
  const ForceModel<float> f = test::all_local_terms<float>();
  for (const Method* m : {&rk4, &velocity_verlet}) {
    StepperOptions o;
    o.jobs = &pool;
    o.workers = WorkerChoice::all;
    CHECK(run_hash(*m, f, o) == run_hash(*m, f, test::serial_options()));
    StepperOptions staged = o;
    staged.force_staged = true;
    CHECK(run_hash(*m, f, staged) == run_hash(*m, f, test::serial_options()));
  }
  CHECK(pool.max_worker_seen() >= 1);  // the pool's own threads did run tasks
}

TEST_CASE("one scene, every ISA and thread count: one hash", "[determinism][isa]") {
  const ForceModel<float> f = test::all_local_terms<float>();
  std::map<std::uint64_t, int> hashes;
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    for (unsigned threads : {1u, 2u, 3u, 8u}) {
      TbbJobSystem tbb(threads);
      StepperOptions o;
      o.isa = isa;
      o.jobs = &tbb;
      o.workers = WorkerChoice::all;
      ++hashes[run_hash(rk4, f, o, 5000, 10)];
    }
  }
  CHECK(hashes.size() == 1);
}

TEST_CASE("advance(n) gives the bits of n calls to step()", "[determinism]") {
  for (bool staged : {false, true}) {
    const ForceModel<double> f = test::all_local_terms<double>();
    StepperOptions o = test::serial_options();
    o.force_staged = staged;
    ParticleSet<double> a = test::cloud<double>(5000), b = a;
    Stepper<double> sa(f, rk4, o), sb(f, rk4, o);
    sa.advance(a, 0.01, 25);
    for (int k = 0; k < 25; ++k) sb.step(b, 0.01);
    CHECK(test::state_hash(a) == test::state_hash(b));
    CHECK(sa.time() == sb.time());
  }
}

TEST_CASE("the block path: advance(n) with a time-dependent callback gives the bits of n steps",
          "[determinism]") {
  ForceModel<double> f = test::all_local_terms<double>();
  f.add([](const ParticleBlock<double>& b) {
    for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += std::sin(3 * b.t) * b.px[i] + b.vz[i];
  });
  for (const Method* m : {&rk4, &velocity_verlet, &dopri5}) {
    INFO(m->name);
    ParticleSet<double> a = test::cloud<double>(5000), b = a;
    Stepper<double> sa(f, *m, test::serial_options()), sb(f, *m, test::serial_options());
    sa.set_time(0.25), sb.set_time(0.25);
    sa.advance(a, 0.01, 25);
    for (int k = 0; k < 25; ++k) sb.step(b, 0.01);
    CHECK(test::state_hash(a) == test::state_hash(b));
    CHECK(sa.time() == sb.time());
  }
}

TEST_CASE("the relaxed scalar and SSE2 builds stay deterministic and close", "[determinism][isa]") {
  const ForceModel<float> f = test::all_local_terms<float>();
  for (Isa isa : {Isa::scalar, Isa::sse2}) {
    if (!isa_available(isa)) continue;
    StepperOptions relaxed = test::serial_options(isa);
    relaxed.relaxed_fma = true;
    ParticleSet<float> exact = test::cloud<float>(2000), fast = exact;
    Stepper<float>(f, rk4, test::serial_options(isa)).advance(exact, 0.01f, 20);
    Stepper<float>(f, rk4, relaxed).advance(fast, 0.01f, 20);
    INFO(isa_name(isa));
#ifdef KINEMA_KERNELS_RELAXED
    CHECK(test::state_hash(fast) != test::state_hash(exact));  // it really is another build
#else
    CHECK(test::state_hash(fast) == test::state_hash(exact));  // built without: the exact kernels
#endif
    for (std::size_t i = 0; i < exact.size(); ++i) {
      REQUIRE(exact.px()[i] == Approx(fast.px()[i]).epsilon(1e-5).margin(1e-5));
    }
    TbbJobSystem two(2);
    relaxed.jobs = &two;
    relaxed.workers = WorkerChoice::all;
    ParticleSet<float> again = test::cloud<float>(2000);
    Stepper<float>(f, rk4, relaxed).advance(again, 0.01f, 20);
    CHECK(test::state_hash(again) == test::state_hash(fast));
  }
}
