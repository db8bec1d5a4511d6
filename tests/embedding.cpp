// What an engine that embeds kinema relies on: a throwing callback leaves the set as it
// was, the job-system contract (several host threads, re-entrant calls, a dedicated physics
// thread), and inline_below counting real bodies.
#include <catch2/catch.hpp>

#include <stdexcept>
#include <thread>

#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

// Forces from user code that throws on one block at one stage time.
ForceModel<double> throwing_model(std::size_t block_begin, double at_time) {
  ForceModel<double> f = test::all_local_terms<double>();
  f.add([=](const ParticleBlock<double>& b) {
    if (b.begin == block_begin && b.t == at_time) throw std::runtime_error("callback failed");
    for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += 0.1 * b.px[i];
  });
  return f;
}

void check_throw_leaves_state(const Method& method, StepperOptions o) {
  ParticleSet<double> b = test::cloud<double>(5000);
  // The second stage time of the second step: some blocks have finished, others not.
  const double h = 0.01, t = h + method.tableau.c[1] * h;
  const double when = method.kind == MethodKind::runge_kutta ? t : h + h;
  Stepper<double> s(throwing_model(2048, when), method, o);
  s.step(b, h);
  const std::uint64_t before = test::state_hash(b);
  CHECK_THROWS_WITH(s.step(b, h), "callback failed");
  CHECK(test::state_hash(b) == before);
  CHECK(s.time() == h);
  // The stepper stays usable: a step at another time goes through.
  s.set_time(5);
  s.step(b, h);
  CHECK(test::state_hash(b) != before);
}

}  // namespace

TEST_CASE("a callback that throws leaves the set as before the step, on any job system",
          "[embedding]") {
  TbbJobSystem tbb(2);
  test::ThreadPool pool(2);
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    check_throw_leaves_state(*m, test::serial_options());
    for (JobSystem* jobs : {static_cast<JobSystem*>(&tbb), static_cast<JobSystem*>(&pool)}) {
      StepperOptions o;
      o.jobs = jobs;
      o.inline_below = 0;
      check_throw_leaves_state(*m, o);
    }
  }
}

namespace {

// Counts the jobs it is given and runs them inline.
class CountingJobs final : public JobSystem {
 public:
  unsigned worker_count() const override { return 2; }
  JobHandle enqueue(RangeTask task, std::size_t count, std::size_t, void* context) override {
    ++jobs;
    task(0, count, 0, context);
    return nullptr;
  }
  void wait(JobHandle) override {}
  int jobs = 0;
};

}  // namespace

TEST_CASE("inline_below counts real bodies, not padding", "[embedding]") {
  for (std::size_t count : {8191u, 8192u}) {
    CountingJobs jobs;
    StepperOptions o;
    o.jobs = &jobs;
    ParticleSet<float> b = test::cloud<float>(count);
    Stepper<float>(test::all_local_terms<float>(), rk4, o).step(b, 0.01f);
    CHECK(jobs.jobs == (count < o.inline_below ? 0 : 1));
  }
}

namespace {

std::uint64_t stepped_hash(StepperOptions o) {
  ParticleSet<double> b = test::cloud<double>(5000);
  Stepper<double> s(test::all_local_terms<double>(), rk4, o);
  s.advance(b, 0.01, 3);
  return test::state_hash(b);
}

StepperOptions on(JobSystem& jobs) {
  StepperOptions o;
  o.jobs = &jobs;
  o.inline_below = 0;
  return o;
}

}  // namespace

TEST_CASE("job systems: several host threads at once, calls from inside a task, a physics "
          "thread", "[embedding][job_system]") {
  const std::uint64_t serial = stepped_hash(test::serial_options());
  TbbJobSystem tbb(2);
  test::ThreadPool pool(2);
  for (JobSystem* jobs : {static_cast<JobSystem*>(&tbb), static_cast<JobSystem*>(&pool)}) {
    // Two host threads step their own sets through the same job system at once.
    std::uint64_t a = 0, b = 0;
    std::thread first([&] { a = stepped_hash(on(*jobs)); });
    std::thread second([&] { b = stepped_hash(on(*jobs)); });
    first.join();
    second.join();
    CHECK(a == serial);
    CHECK(b == serial);
    // A task of the job system itself steps a set through the same job system.
    struct Nested {
      JobSystem* jobs;
      std::uint64_t hash = 0;
    } nested{jobs};
    const RangeTask task = [](std::size_t, std::size_t, unsigned, void* context) {
      auto& n = *static_cast<Nested*>(context);
      n.hash = stepped_hash(on(*n.jobs));
    };
    jobs->wait(jobs->enqueue(task, 1, 1, &nested));
    CHECK(nested.hash == serial);
  }
  // One worker that is not the calling thread: the blocks run there.
  test::ThreadPool physics(1, false);
  REQUIRE(physics.worker_count() == 1);
  CHECK(stepped_hash(on(physics)) == serial);
  CHECK(physics.ranges_on_pool_threads() > 0);
}
