// The job systems run every item exactly once, with worker indices in range.
#include <catch2/catch.hpp>

#include <atomic>
#include <vector>

#include "kinema/job_system.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

struct Tally {
  std::vector<std::atomic<int>> hits;
  std::atomic<unsigned> max_worker{0};
  explicit Tally(std::size_t n) : hits(n) {}
};

void count_range(std::size_t begin, std::size_t end, unsigned worker, void* context) {
  auto& t = *static_cast<Tally*>(context);
  for (std::size_t i = begin; i < end; ++i) ++t.hits[i];
  unsigned seen = t.max_worker.load();
  while (worker > seen && !t.max_worker.compare_exchange_weak(seen, worker)) {
  }
}

void check_each_item_once(JobSystem& jobs, std::size_t items, std::size_t min_range) {
  Tally tally(items);
  jobs.wait(jobs.enqueue(&count_range, items, min_range, &tally));
  for (std::size_t i = 0; i < items; ++i) REQUIRE(tally.hits[i] == 1);
  CHECK(tally.max_worker < jobs.worker_count());
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

TEST_CASE("the default TBB job system uses every hardware thread", "[job_system]") {
  TbbJobSystem tbb;
  CHECK(tbb.worker_count() == hardware_threads());
  CHECK(hardware_threads() >= 1);
}
