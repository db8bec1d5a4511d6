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
