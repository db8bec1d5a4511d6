// The job systems run every item exactly once, with worker indices in range.
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include <sched.h>

#include "kinema/error.hpp"

#include "kinema/job_system.hpp"
#include "parallel/cores.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

struct Tally {
  std::vector<std::atomic<int>> hits;
  std::size_t min_range;
  std::atomic<unsigned> max_worker{0};
  std::atomic<int> short_ranges{0};  // shorter than min_range and not at the end
  Tally(std::size_t n, std::size_t min) : hits(n), min_range(min) {}
};

void count_range(std::size_t begin, std::size_t end, unsigned worker, void* context) {
  auto& t = *static_cast<Tally*>(context);
  for (std::size_t i = begin; i < end; ++i) ++t.hits[i];
  if (end - begin < t.min_range && end != t.hits.size()) ++t.short_ranges;
  unsigned seen = t.max_worker.load();
  while (worker > seen && !t.max_worker.compare_exchange_weak(seen, worker)) {
  }
}

void check_each_item_once(JobSystem& jobs, std::size_t items, std::size_t min_range) {
  Tally tally(items, min_range);
  jobs.wait(jobs.enqueue(&count_range, items, min_range, &tally));
  for (std::size_t i = 0; i < items; ++i) REQUIRE(tally.hits[i] == 1);
  CHECK(tally.max_worker < jobs.worker_count());
  CHECK(tally.short_ranges == 0);
}

}  // namespace

TEST_CASE("job systems run every item exactly once", "[job_system]") {
  SerialJobSystem serial;
  CHECK(serial.worker_count() == 1);
  check_each_item_once(serial, 1000, 1);
  for (unsigned threads : {1u, 2u, 4u}) {
    TbbJobSystem tbb(threads);
    CHECK(tbb.worker_count() == threads);
    check_each_item_once(tbb, 1000, 1);
    check_each_item_once(tbb, 7, 3);
    check_each_item_once(tbb, 0, 1);
  }
  test::ThreadPool pool(2);
  check_each_item_once(pool, 1000, 4);
}

// TbbJobSystem gives each worker a slice and lets idle workers take from the backs of the
// others' slices: every split must still cover each item once (with 8 threads on fewer
// cores, most slices are taken by thieves).
TEST_CASE("the TBB job system covers every item for any count, grain and thread count",
          "[job_system]") {
  for (unsigned threads : {1u, 2u, 3u, 8u}) {
    TbbJobSystem tbb(threads);
    for (std::size_t items : {1u, 2u, 5u, 97u, 98u, 1000u}) {
      for (std::size_t min_range : {1u, 3u, 64u}) {
        INFO(threads << " threads, " << items << " items, min_range " << min_range);
        check_each_item_once(tbb, items, min_range);
      }
    }
  }
}

TEST_CASE("the default TBB job system uses every hardware thread", "[job_system]") {
  TbbJobSystem tbb;
  CHECK(tbb.worker_count() == hardware_threads());
  CHECK(hardware_threads() >= 1);
}

// A TbbJobSystem's workers spin after a job (WorkerSpin::after_job), then sleep, and their
// tasks end after spin.linger; jobs posted in each of those states, from several host threads
// at once and from inside a job, still run every item once.
TEST_CASE("the TBB job system's workers spin after a job for after_job, then sleep", "[job_system]") {
  WorkerSpin spin;
  spin.after_job = std::chrono::milliseconds(5);
  TbbJobSystem jobs(2, spin);
  // The worker's task spins 5 ms after a job it took part in (a spin is counted as it ends),
  // then sleeps. Its task may start late (oneTBB's thread busy elsewhere, or a loaded machine),
  // the calling thread running whole jobs alone meanwhile: jobs are posted until it spins.
  for (int k = 0; k < 200 && jobs.spin_seconds() == 0; ++k) {
    check_each_item_once(jobs, 1000, 1);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  REQUIRE(jobs.spin_seconds() > 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const double spun = jobs.spin_seconds();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  CHECK(jobs.spin_seconds() == spun);  // asleep: no more spinning
  check_each_item_once(jobs, 1000, 1);  // a sleeping worker is woken (or left out)
}

TEST_CASE("the TBB job system with no spin never spins, and runs jobs after its tasks ended", "[job_system]") {
  WorkerSpin spin;
  spin.after_job = std::chrono::microseconds(0);
  spin.linger = std::chrono::microseconds(2000);
  TbbJobSystem jobs(2, spin);
  for (int round = 0; round < 3; ++round) {
    check_each_item_once(jobs, 5000, 1);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the task ends meanwhile
  }
  CHECK(jobs.spin_seconds() == 0);
}

TEST_CASE("the TBB job system serves several host threads at once and jobs made inside a job", "[job_system]") {
  TbbJobSystem jobs(3);
  std::vector<std::thread> hosts;
  std::atomic<int> bad{0};
  for (int h = 0; h < 3; ++h) {
    hosts.emplace_back([&] {
      for (int k = 0; k < 200; ++k) {
        Tally tally(300, 1);
        jobs.wait(jobs.enqueue(&count_range, 300, 1, &tally));
        for (auto& hit : tally.hits) bad += hit != 1;
      }
    });
  }
  for (auto& t : hosts) t.join();
  CHECK(bad == 0);
  // A job whose items each run a job of their own on the same system.
  struct Nested {
    TbbJobSystem* jobs;
    std::atomic<int> bad{0};
  } nested{&jobs};
  const RangeTask outer = [](std::size_t begin, std::size_t end, unsigned, void* context) {
    auto& n = *static_cast<Nested*>(context);
    for (std::size_t i = begin; i < end; ++i) {
      Tally tally(64, 1);
      n.jobs->wait(n.jobs->enqueue(&count_range, 64, 1, &tally));
      for (auto& hit : tally.hits) n.bad += hit != 1;
    }
  };
  jobs.wait(jobs.enqueue(outer, 40, 1, &nested));
  CHECK(nested.bad == 0);
}

TEST_CASE("KINEMA_WORKER_SPIN_US must be a whole number of microseconds", "[job_system]") {
  // default_job_system reads it when it makes a system; a number of threads no other test
  // uses makes a new one.
  const char* outer = std::getenv("KINEMA_WORKER_SPIN_US");  // the test run's own
  const std::string kept = outer != nullptr ? outer : "";
  setenv("KINEMA_WORKER_SPIN_US", "20ms", 1);
  CHECK_THROWS_WITH(default_job_system(7), Catch::Contains("KINEMA_WORKER_SPIN_US") && Catch::Contains("20ms"));
  setenv("KINEMA_WORKER_SPIN_US", "-5", 1);
  CHECK_THROWS_AS(default_job_system(7), Error);
  setenv("KINEMA_WORKER_SPIN_US", "0", 1);
  CHECK(default_job_system(7).worker_count() == 7);
  if (outer != nullptr) setenv("KINEMA_WORKER_SPIN_US", kept.c_str(), 1);
  else unsetenv("KINEMA_WORKER_SPIN_US");
}

TEST_CASE("leave_core moves a thread off a core and gives it back the cores it may use", "[job_system]") {
  cpu_set_t allowed;
  REQUIRE(sched_getaffinity(0, sizeof allowed, &allowed) == 0);
  // On a thread of its own, whose results the test's thread checks (Catch asserts there).
  int here = -1;
  bool moved = false, same_mask = false, left_none = true;
  std::thread([&] {
    here = kinema::detail::current_cpu();
    moved = kinema::detail::leave_core(here);
    cpu_set_t after;
    same_mask = sched_getaffinity(0, sizeof after, &after) == 0 && CPU_EQUAL(&after, &allowed);
    left_none = kinema::detail::leave_core(-1);  // no such core: nothing to leave
  }).join();
  REQUIRE(here >= 0);
  CHECK(same_mask);
  CHECK(moved == (CPU_COUNT(&allowed) > 1));  // nowhere else to go on one core
  CHECK_FALSE(left_none);
}
