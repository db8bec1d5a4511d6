// The measured worker choice: it settles on the cheapest option, retries the others at a
// bounded cost, follows a change of costs, and shrugs off a pre-empted call and the cost of
// switching. Costs are simulated (ticks per body-step), so the facts are exact.
#include <catch2/catch.hpp>

#include <algorithm>
#include <functional>
#include <vector>

#include "parallel/blocks.hpp"
#include "kinema/kinema.hpp"
#include "support.hpp"
#include "thread_pool.hpp"
#include "parallel/worker_tuner.hpp"

using namespace kinema;

namespace {

// Ticks per unit of work for `count` workers, given the count of the call before.
using CostModel = std::function<double(unsigned count, unsigned previous)>;

struct Run {
  double spent = 0;    // ticks in all
  std::vector<unsigned> counts;
};

Run drive(WorkerTuner& tuner, int calls, const CostModel& cost, unsigned previous = 0) {
  Run run;
  for (int k = 0; k < calls; ++k) {
    const unsigned count = tuner.choose();
    const double ticks = 1000 * cost(count, previous);
    tuner.record(count, std::uint64_t(ticks), 1000);
    run.spent += ticks;
    run.counts.push_back(count);
    previous = count;
  }
  return run;
}

CostModel flat(double inline_cost, double two_cost) {
  return [=](unsigned count, unsigned) { return count == 0 ? inline_cost : two_cost; };
}

}  // namespace

TEST_CASE("the worker tuner settles on the cheaper option and retries the other at about 1% of the time",
          "[worker_tuner]") {
  for (const auto& [inline_cost, two_cost, winner] :
       {std::tuple{1.0, 0.6, 2u}, std::tuple{0.6, 1.0, 0u}, std::tuple{1.0, 25.0, 0u}}) {
    INFO("inline " << inline_cost << ", 2 workers " << two_cost);
    WorkerTuner tuner(2);
    drive(tuner, 50, flat(inline_cost, two_cost));
    CHECK(tuner.best() == winner);
    // While few samples confirm the loser it is retried sooner (after 8, 16, 32 ... calls): a
    // one-time cost, at most that of about 10 retries of 2 calls at 25x in 5000 calls.
    const Run confirming = drive(tuner, 5000, flat(inline_cost, two_cost));
    CHECK(confirming.spent / (5000 * 1000 * std::min(inline_cost, two_cost)) - 1 < 0.1);
    const Run settled = drive(tuner, 20000, flat(inline_cost, two_cost));
    const double best_cost = std::min(inline_cost, two_cost);
    const double overhead = settled.spent / (20000 * 1000 * best_cost) - 1;
    CHECK(overhead > 0);        // it does retry
    CHECK(overhead < 0.015);    // a retry (2 calls) spread over about 200 calls
  }
}

TEST_CASE("the worker tuner undoes a choice misjudged on a cold start within tens of calls", "[worker_tuner]") {
  // A job system's first calls start its threads and warm its caches: 2 workers cost 20x for
  // their first 6 calls (each of the 3 settling samples and the switch before it), then 0.6
  // of the calling thread alone.
  int two_calls = 0;
  const CostModel cold = [&](unsigned count, unsigned) {
    if (count == 0) return 1.0;
    return ++two_calls <= 6 ? 20.0 : 0.6;
  };
  WorkerTuner tuner(2);
  drive(tuner, 12, cold);
  REQUIRE(tuner.best() == 0);  // misjudged, as it must be on those samples
  const Run next = drive(tuner, 60, cold);
  CHECK(tuner.best() == 2);
  // Retried after 8 calls and 16, the lower cost seen twice in a row believed at once (the
  // settled period alone would put the next retry of a 19x option 3600 calls away).
  CHECK(std::count(next.counts.end() - 20, next.counts.end(), 2u) >= 19);
}

TEST_CASE("the worker tuner follows a change of costs", "[worker_tuner]") {
  WorkerTuner tuner(2);
  drive(tuner, 5000, flat(1.0, 0.6));
  REQUIRE(tuner.best() == 2);
  // The other core gets busy: 2 workers now cost more than the calling thread alone.
  const Run after = drive(tuner, 300, flat(0.6, 1.0), 2);
  CHECK(tuner.best() == 0);
  int late_twos = 0;
  for (std::size_t k = 200; k < after.counts.size(); ++k) late_twos += after.counts[k] == 2;
  CHECK(late_twos <= 2);  // retries only: 2 calls about every 135
}

TEST_CASE("the worker tuner ignores a pre-empted call and the first call after a switch",
          "[worker_tuner]") {
  SECTION("one call taking 100x") {
    WorkerTuner tuner(2);
    drive(tuner, 200, flat(1.0, 0.6));
    REQUIRE(tuner.best() == 2);
    tuner.record(tuner.choose(), 60000 * 100, 1000);
    CHECK(tuner.best() == 2);
  }
  SECTION("waking the workers costs the first call after the calling thread ran alone") {
    // Back to back, 2 workers are cheaper; only a call right after an inline one pays the wake.
    const CostModel wake = [](unsigned count, unsigned previous) {
      if (count == 0) return 1.0;
      return previous == 0 ? 3.0 : 0.6;
    };
    WorkerTuner tuner(2);
    drive(tuner, 200, wake);
    CHECK(tuner.best() == 2);
  }
}

TEST_CASE("the worker tuner: one worker is the only option, more give 0 and 2 .. n",
          "[worker_tuner]") {
  WorkerTuner single(1);
  for (int k = 0; k < 20; ++k) {
    CHECK(single.choose() == 1);
    single.record(1, 100, 1);
  }
  WorkerTuner four(4);
  std::vector<unsigned> seen = drive(four, 40, [](unsigned count, unsigned) { return 1.0 + count; }).counts;
  std::sort(seen.begin(), seen.end());
  seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
  CHECK(seen == std::vector<unsigned>{0, 2, 3, 4});
  CHECK(four.best() == 0);
}

namespace {

// Records the min_range of each job and runs it inline.
class RecordingJobs final : public JobSystem {
 public:
  explicit RecordingJobs(unsigned workers) : workers_(workers) {}
  unsigned worker_count() const override { return workers_; }
  JobHandle enqueue(RangeTask task, std::size_t count, std::size_t min_range, void* context) override {
    min_ranges.push_back(min_range);
    task(0, count, 0, context);
    return nullptr;
  }
  void wait(JobHandle) override {}
  void wake() override { ++wakes; }
  std::vector<std::size_t> min_ranges;
  int wakes = 0;

 private:
  unsigned workers_;
};

}  // namespace

TEST_CASE("a call meant for k workers asks for ranges of at least blocks / k", "[worker_tuner]") {
  RecordingJobs jobs(8);
  const std::size_t bodies = 10 * kBlockBodies;
  int blocks = 0;
  for (unsigned k : {0u, 1u, 2u, 3u, 8u}) for_each_block(Workers{&jobs, k}, bodies, [&](Block) { ++blocks; });
  CHECK(blocks == 50);
  CHECK(jobs.min_ranges == std::vector<std::size_t>{10, 5, 4, 1});  // 0 workers: no job; all 8: any split
}

TEST_CASE("measured worker counts on a TBB job system keep every result's bits while the choice changes",
          "[worker_tuner][job_system]") {
  ParticleSet<double> serial = test::cloud<double>(5000);
  ParticleSet<double> measured = serial;
  Stepper<double>(test::all_local_terms<double>(), rk4, test::serial_options()).advance(serial, 0.01, 40);
  TbbJobSystem tbb(2);
  StepperOptions o;
  o.jobs = &tbb;
  Stepper<double> stepper(test::all_local_terms<double>(), rk4, o);
  for (int k = 0; k < 40; ++k) stepper.step(measured, 0.01);  // first use tries both options
  CHECK(test::state_hash(measured) == test::state_hash(serial));
  CHECK((stepper.chosen_workers() == 0 || stepper.chosen_workers() == 2));
}

TEST_CASE("measured choice: a host's single physics thread gets every call", "[worker_tuner]") {
  RecordingJobs physics(1);
  StepperOptions o;
  o.jobs = &physics;
  ParticleSet<float> b = test::cloud<float>(5000);
  Stepper<float> stepper(test::all_local_terms<float>(), rk4, o);
  for (int k = 0; k < 30; ++k) stepper.step(b, 0.01f);
  CHECK(physics.min_ranges.size() == 30);
  CHECK(stepper.chosen_workers() == 1);
}

TEST_CASE("prepare wakes the workers only when the next call is to use them", "[worker_tuner]") {
  ParticleSet<float> b = test::cloud<float>(5000);
  SECTION("every call on all workers") {
    RecordingJobs jobs(2);
    StepperOptions o;
    o.jobs = &jobs;
    o.workers = WorkerChoice::all;
    Stepper<float> stepper(test::all_local_terms<float>(), rk4, o);
    stepper.prepare();
    CHECK(jobs.wakes == 1);
  }
  SECTION("measured: nothing to go on before the first call, then the tuner's next choice") {
    RecordingJobs jobs(2);
    StepperOptions o;
    o.jobs = &jobs;
    Stepper<float> stepper(test::all_local_terms<float>(), rk4, o);
    stepper.prepare();
    CHECK(jobs.wakes == 0);
    // First use tries the calling thread twice (the first call after a switch is not kept),
    // then 2 workers: the third call's prepare wakes them.
    int woken_before[4];
    for (int k = 0; k < 4; ++k) {
      const int before = jobs.wakes;
      stepper.prepare();
      woken_before[k] = jobs.wakes - before;
      stepper.step(b, 0.01f);
    }
    CHECK(woken_before[0] == 0);
    CHECK(woken_before[1] == 0);
    CHECK(woken_before[2] == 1);
    CHECK(woken_before[3] == 1);
    CHECK(jobs.min_ranges.size() == 2);  // the calls on 2 workers went to the job system
  }
  SECTION("a single worker, or the calling thread: never") {
    RecordingJobs physics(1);
    StepperOptions o;
    o.jobs = &physics;
    Stepper<float> stepper(test::all_local_terms<float>(), rk4, o);
    for (int k = 0; k < 5; ++k) stepper.prepare(), stepper.step(b, 0.01f);
    CHECK(physics.wakes == 0);
  }
}
