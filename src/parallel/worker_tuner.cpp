#include "parallel/worker_tuner.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#if defined(__x86_64__)
#include <x86intrin.h>
#endif

namespace kinema {
namespace {

constexpr unsigned kNone = WorkerTuner::kMaxOptions;
// Kept samples of each option before the choice settles.
constexpr unsigned kFirstSamples = 3;
// Calls between retries of an option that costs `ratio` times the best: a retry is two calls
// (the first after a switch is not kept), their extra cost spread over about 200 calls of the
// best (1%), at least every 8 calls, at most every 4096. An option judged on few samples may
// have been judged on a cold start (a job system's first use starts its threads: 5 ms, 500
// times a small step): it is retried within 8 calls of its settling, then 16, 32 ... as its
// kept samples confirm it, so a misjudged option comes back within tens of calls.
std::uint64_t retry_period(double ratio, unsigned samples) {
  const double calls = std::ceil(200 * (ratio - 1));
  const unsigned confirmed = std::min(samples - std::min(samples, kFirstSamples), 9u);
  return std::uint64_t(std::clamp(calls, 8.0, double(8u << confirmed)));
}

}  // namespace

std::uint64_t tuner_ticks() {
#if defined(__x86_64__)
  return __rdtsc();
#else
  return std::uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
#endif
}

WorkerTuner::WorkerTuner(unsigned workers) {
  if (workers <= 1) {
    option_[0].count = 1;
    options_ = 1;
    return;
  }
  options_ = std::min(workers, kMaxOptions);  // 0, then 2 .. workers
  for (unsigned i = 0; i < options_; ++i) option_[i].count = i == 0 ? 0 : i + 1;
  last_ = kNone;
}

unsigned WorkerTuner::index_of(unsigned count) const {
  for (unsigned i = 0; i < options_; ++i) {
    if (option_[i].count == count) return i;
  }
  return kNone;
}

unsigned WorkerTuner::choose() const {
  if (options_ == 1) return option_[0].count;
  // Settling: the option with the fewest kept samples.
  unsigned fewest = 0;
  for (unsigned i = 1; i < options_; ++i) {
    if (option_[i].samples < option_[fewest].samples) fewest = i;
  }
  if (option_[fewest].samples < kFirstSamples) return option_[fewest].count;
  for (unsigned i = 0; i < options_; ++i) {
    if (i != best_ && calls_ >= option_[i].retry_at) return option_[i].count;
  }
  return option_[best_].count;
}

void WorkerTuner::record(unsigned count, std::uint64_t ticks, double work) {
  const unsigned i = index_of(count);
  if (i == kNone || !(work > 0)) return;
  ++calls_;
  // The first call after a switch pays for the switch (workers to wake, caches another core
  // filled): not what the option costs when it runs call after call. choose() keeps asking
  // for an option until a call of it is kept.
  const bool switched = i != last_;
  last_ = i;
  if (switched) return;
  Option& o = option_[i];
  const double x = double(ticks) / work;
  if (o.samples < kFirstSamples) {
    o.cost = o.samples == 0 ? x : std::min(o.cost, x);  // the least disturbed of the first
  } else {
    // The median of the last three: one pre-empted call moves nothing, a real change shows
    // in two. A machine's noise only slows calls down: a lower median is taken at once (a
    // cold start's samples forgotten), a higher one a quarter at a time.
    const double median = std::max(std::min(x, o.recent[0]), std::min(std::max(x, o.recent[0]), o.recent[1]));
    o.cost = median < o.cost ? median : o.cost + (median - o.cost) / 4;
  }
  o.recent[1] = o.recent[0];
  o.recent[0] = x;
  ++o.samples;
  update_best();
  if (i != best_) o.retry_at = calls_ + retry_period(o.cost / option_[best_].cost, o.samples);
}

void WorkerTuner::update_best() {
  unsigned best = best_;
  for (unsigned i = 0; i < options_; ++i) {
    if (option_[i].samples > 0 && (option_[best].samples == 0 || option_[i].cost < option_[best].cost)) best = i;
  }
  if (best == best_) return;
  Option& previous = option_[best_];
  best_ = best;
  if (previous.samples > 0) {
    previous.retry_at = calls_ + retry_period(previous.cost / option_[best_].cost, previous.samples);
  }
}

WorkerTuner& WorkerTuners::find(std::uint64_t key, unsigned workers) {
  ++clock_;
  Slot* oldest = &slot_[0];
  for (Slot& s : slot_) {
    if (s.used != 0 && s.key == key) {
      s.used = clock_;
      return s.tuner;
    }
    if (s.used < oldest->used) oldest = &s;
  }
  *oldest = Slot{key, clock_, WorkerTuner(workers)};
  return oldest->tuner;
}

}  // namespace kinema
