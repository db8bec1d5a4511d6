// No allocation inside step or advance, on either path, with TBB or serial jobs: a counting
// global operator new watches every allocation of the process.
#include <catch2/catch.hpp>

#include <atomic>
#include <cstdlib>
#include <new>

#include "support.hpp"

namespace {
std::atomic<long> g_allocations{0};
}

void* operator new(std::size_t size) {
  ++g_allocations;
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

using namespace kinema;

namespace {

template <class T>
long allocations_in_steps(const Method& method, ForceModel<T> forces, bool staged, bool tbb) {
  ParticleSet<T> bodies = test::cloud<T>(30000);
  TbbJobSystem jobs(2);
  StepperOptions o = tbb ? StepperOptions{} : test::serial_options();
  if (tbb) o.jobs = &jobs, o.inline_below = 0;
  o.force_staged = staged;
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

}  // namespace

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
