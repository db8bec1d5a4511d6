#include "step/event_watch.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <new>
#include <string>
#include <type_traits>

#include "core/text.hpp"
#include "kinema/dense_output.hpp"
#include "kinema/error.hpp"
#include "parallel/blocks.hpp"
#include "step/finite_guard.hpp"
#include "step/rigid_block_path.hpp"
#include "step/step_checks.hpp"

namespace kinema {

namespace {

using Vec = std::array<double, 3>;

constexpr std::size_t kMaxWidth = 16;  // SIMD lanes

// Whether key a comes first: by time, body, event.
template <class Key>
bool before(const Key& a, const Key& b) {
  const bool body_first = (a.body < b.body) | ((a.body == b.body) & (a.event < b.event));
  return (a.time < b.time) | ((a.time == b.time) & body_first);
}

// Inserts each key after those before it: a pass, and a move per key out of order.
template <class Key>
void insertion_sort(Key* keys, std::size_t n) {
  for (std::size_t i = 1; i < n; ++i) {
    const Key key = keys[i];
    std::size_t j = i;
    for (; j > 0 && before(key, keys[j - 1]); --j) keys[j] = keys[j - 1];
    keys[j] = key;
  }
}

double dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

bool finite(const Vec& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

[[noreturn]] void refuse(std::size_t e, const std::string& what) {
  throw Error("events[" + std::to_string(e) + "]: " + what);
}

// A user's value that is NaN has no sign: no crossing could be found in it, or ruled out.
template <class T>
void check_given(int e, const T* values, std::size_t count, std::size_t first, double t) {
  for (std::size_t i = 0; i < count; ++i) {
    if (std::isnan(values[i])) {
      refuse(std::size_t(e), "the event function gave NaN for body " + std::to_string(first + i) + " at t = " +
                                 shortest_text(t));
    }
  }
}

// An event's value at a fraction of the step, and its slope there where known (NaN if not).
struct Sample {
  double value, slope;
};

// Where the next value is taken: the Newton point of the last sample where it lies inside the
// bracket, else regula falsi (with the Anderson-Bjorck scaling), a bisection past 40 tries.
// A Newton point within half the tolerance of the last one steps half the tolerance past it,
// so a bracket closing from one side closes.
double next_fraction(const Sample& last, double m, double lo, double hi, double g_lo, double g_hi,
                     double tolerance, int iteration) {
  double next = m - last.value / last.slope;
  if (std::abs(next - m) < 0.5 * tolerance) next = next > m ? m + 0.5 * tolerance : m - 0.5 * tolerance;
  if (next > lo && next < hi) return next;
  next = iteration < 40 ? (lo * g_hi - hi * g_lo) / (g_hi - g_lo) : 0.5 * (lo + hi);
  return next > lo && next < hi ? next : 0.5 * (lo + hi);
}

// The fraction of the step at which g changes sign, g(0) and g(1) on either side (or g(1)
// zero): safeguarded Newton where g gives its slope (4 to 6 values on a step's cubic),
// regula falsi otherwise (6 to 9). Returns the bracket's end past the crossing once the
// bracket is at most `tolerance` wide (at least a few ulps of the fraction).
template <class G>
double crossing_fraction(G&& g, double tolerance) {
  tolerance = std::max(tolerance, 4 * std::numeric_limits<double>::epsilon());
  const Sample first = g(0.0);
  double lo = 0, hi = 1, g_lo = first.value, g_hi = g(1.0).value;
  if (g_lo == 0) return 0;
  if ((g_lo > 0) == (g_hi > 0) && g_hi != 0) return std::abs(g_hi) <= std::abs(g_lo) ? 1 : 0;  // round-off
  Sample last = first;
  double m = 0;
  int kept = 0;  // the end the last value did not replace: +1 hi, -1 lo
  for (int iteration = 0; iteration < 200 && hi - lo > tolerance; ++iteration) {
    m = next_fraction(last, m, lo, hi, g_lo, g_hi, tolerance, iteration);
    if (!(m > lo && m < hi)) break;  // lo and hi are neighbours
    last = g(m);
    if (last.value == 0) return m;
    if ((last.value > 0) == (g_lo > 0)) {
      const double scale = 1 - last.value / g_lo;
      if (kept == +1) g_hi *= scale > 0 ? scale : 0.5;
      lo = m, g_lo = last.value, kept = +1;
    } else {
      const double scale = 1 - last.value / g_hi;
      if (kept == -1) g_lo *= scale > 0 ? scale : 0.5;
      hi = m, g_hi = last.value, kept = -1;
    }
  }
  return hi;
}

// One component of a body's path over the step: the cubic Hermite of its ends and rates plus
// dopri5's own term r (theta (1 - theta))^2 (r = 0 for other methods), as
// y0 + c1 theta + ... + c4 theta^4, the differences formed once (little cancellation when y
// is large). Both ends are exact: a value at zero at the step's end is seen there.
struct Curve {
  double c0, c1, c2, c3, c4, end;
  static Curve of(double y0, double rate0, double y1, double rate1, double h, double r) {
    const double d = y1 - y0, r0 = h * rate0, r1 = h * rate1;
    return {y0, r0, 3 * d - 2 * r0 - r1 + r, r0 + r1 - 2 * d - 2 * r, r, y1};
  }
  // Without dopri5's term (c4 = 0) its product and sum are left out: they add zeros, and the
  // root finder waits on each value.
  double at(double t) const {
    if (t == 1) return end;
    return c0 + t * (c1 + t * (c2 + t * (c4 == 0 ? c3 : c3 + t * c4)));
  }
  double slope(double t) const { return c1 + t * (2 * c2 + t * (c4 == 0 ? 3 * c3 : 3 * c3 + t * (4 * c4))); }
};


// The band of coordinates x outside which the plane value a x - b, rounded as the kernels
// form it (the product, then the difference), has a strict sign (sign(a) above, -sign(a)
// below): b / a widened by far more than the product's rounding (relative) and its underflow,
// gradual or flushed to zero where the host sets FTZ / DAZ (absolute: the smallest normal
// number, over a and as a coordinate), then rounded outward to T. False where the band does
// not fit in T.
template <class T>
bool axis_plane_band(T a, T b, T (&band)[2]) {
  const double centre = double(b) / double(a);
  const double width = std::abs(centre) * 32.0 * double(std::numeric_limits<T>::epsilon()) +
                       4.0 * double(std::numeric_limits<T>::min()) * (1.0 / std::abs(double(a)) + 1.0);
  const double low = centre - width, high = centre + width, range = double(std::numeric_limits<T>::max());
  if (!(std::abs(low) < range && std::abs(high) < range)) return false;
  band[0] = std::nextafter(T(low), -std::numeric_limits<T>::infinity());
  band[1] = std::nextafter(T(high), std::numeric_limits<T>::infinity());
  return std::isfinite(band[0]) && std::isfinite(band[1]);
}

}  // namespace

template <class T>
void EventWatch<T>::set(EventOptions<T> options) {
  if (!(std::isfinite(options.time_tolerance) && options.time_tolerance >= 0)) {
    throw Error("events: time_tolerance must be finite and >= 0");
  }
  std::vector<kernels::EventScanJob<T>> jobs;
  bool stops = false;
  for (std::size_t e = 0; e < options.events.size(); ++e) {
    const Event<T>& event = options.events[e];
    const std::string field = "events[" + std::to_string(e) + "]: ";
    check_named(field + "direction", event.direction, Crossing::either);
    check_named(field + "action", event.action, EventAction::stop);
    kernels::EventScanJob<T> job{};
    job.down = event.direction != Crossing::up;
    job.up = event.direction != Crossing::down;
    stops = stops || event.action == EventAction::stop;
    if (const auto* plane = std::get_if<PlaneEvent>(&event.kind)) {
      if (!finite(plane->normal) || !std::isfinite(plane->offset)) refuse(e, "plane normal and offset must be finite");
      // |n|^2 in T's range: n . x is formed in T (the times do not depend on n's length).
      const double length2 = dot(plane->normal, plane->normal);
      if (plane->normal[0] == 0 && plane->normal[1] == 0 && plane->normal[2] == 0) {
        refuse(e, "plane normal must not be zero");
      }
      if (length2 == 0) refuse(e, "plane normal's squared length underflows double: scale it up");
      if (!(length2 <= double(std::numeric_limits<T>::max()))) {
        refuse(e, "plane normal's squared length overflows " + type_name<T>() + ": scale it down");
      }
      for (int d = 0; d < 3; ++d) job.a[d] = T(plane->normal[d]);
      job.b = T(plane->offset);
      const int zeros = int(job.a[0] == 0) + int(job.a[1] == 0) + int(job.a[2] == 0);
      if (zeros == 2) {  // along an axis: one array read instead of three, the same values
        job.value = kernels::EventValue::axis_plane;
        job.axis = job.a[0] != 0 ? 0 : job.a[1] != 0 ? 1 : 2;
        job.banded = axis_plane_band(job.a[job.axis], job.b, job.band);
      }
      if (zeros == 3) refuse(e, "plane normal is zero in this precision");
    } else if (const auto* distance = std::get_if<DistanceEvent>(&event.kind)) {
      if (!finite(distance->point)) refuse(e, "distance point must be finite");
      if (!(std::isfinite(distance->radius) && distance->radius > 0)) refuse(e, "distance radius must be finite and > 0");
      job.value = kernels::EventValue::distance;
      for (int d = 0; d < 3; ++d) job.a[d] = T(distance->point[d]);
      job.b = T(distance->radius * distance->radius);
    } else if (const auto* speed = std::get_if<SpeedEvent>(&event.kind)) {
      if (!(std::isfinite(speed->speed) && speed->speed >= 0)) refuse(e, "speed must be finite and >= 0");
      job.value = kernels::EventValue::speed;
      job.b = T(speed->speed * speed->speed);
    } else if (!std::get<EventFunction<T>>(event.kind)) {
      refuse(e, "the event function is empty");
    }
    if (!std::isfinite(double(job.a[0])) || !std::isfinite(double(job.a[1])) || !std::isfinite(double(job.a[2]))) {
      refuse(e, "distance point overflows the precision");  // a plane's normal: its squared length, above
    }
    if (!std::isfinite(double(job.b))) {
      refuse(e, std::holds_alternative<PlaneEvent>(event.kind)      ? "plane offset overflows the precision"
                : std::holds_alternative<DistanceEvent>(event.kind) ? "distance radius squared overflows the precision"
                                                                    : "speed squared overflows the precision");
    }
    jobs.push_back(job);
  }
  events_ = std::move(options.events);
  jobs_ = std::move(jobs);
  tolerance_ = options.time_tolerance;
  stops_ = stops;
  calls_user_ = std::any_of(events_.begin(), events_.end(),
                            [](const Event<T>& e) { return std::holds_alternative<EventFunction<T>>(e.kind); });
  settled_.reset();
  settled_hits_.clear();
  clear();
}

template <class T>
std::optional<kernels::EventProbe<T>> EventWatch<T>::probe() const {
  if (calls_user_ || jobs_.size() > std::size_t(kernels::kProbeTests)) return std::nullopt;
  kernels::EventProbe<T> probe;
  probe.tests = jobs_.data();
  probe.count = int(jobs_.size());
  return probe;
}

template <class T>
void EventWatch<T>::clear() {
  hits_.clear();
  stop_.reset();
}

template <class T>
void EventWatch<T>::rollback(std::size_t kept) {
  hits_.resize(std::min(kept, hits_.size()));
  stop_.reset();  // the hits kept are of steps before: a stop among them would have ended the call
}

template <class T>
std::optional<typename EventWatch<T>::Stop> EventWatch<T>::first_stop() const {
  std::lock_guard lock(mutex_);
  return stop_;
}

template <class T>
void EventWatch<T>::finish(std::optional<double> until) {
  if (until) std::erase_if(hits_, [&](const EventHit<T>& hit) { return hit.time > *until; });
  // The keys sorted, then the hits gathered once: a hit is twice a key's size and more. Its
  // scratch grows with the hits; where it cannot (finish runs in a destructor, maybe while
  // another error unwinds), the hits are sorted in place.
  try {
    order_.clear();
    for (std::size_t i = 0; i < hits_.size(); ++i) order_.push_back({hits_[i].time, hits_[i].body, hits_[i].event, i});
    sort_keys(order_, merged_, buckets_);
    sorted_.clear();
    for (const HitKey& key : order_) sorted_.push_back(hits_[key.index]);
  } catch (const std::bad_alloc&) {
    std::sort(hits_.begin(), hits_.end(), [](const EventHit<T>& a, const EventHit<T>& b) { return before(a, b); });
    return;
  }
  hits_.swap(sorted_);
}


// A bucket sort by time, then each bucket sorted: each key's bucket rises with its time, so
// the buckets come in order (a step's crossings spread over it: a few keys a bucket, sorted
// by insertion; a crowded bucket by std::sort). Linear where a comparison sort mispredicts
// every other comparison.
template <class T>
void EventWatch<T>::sort_keys(std::vector<HitKey>& keys, std::vector<HitKey>& scratch, std::vector<std::size_t>& ends) {
  const std::size_t n = keys.size();
  const auto sort_run = [](HitKey* begin, HitKey* end) {
    if (end - begin > 16) return std::sort(begin, end, before<HitKey>);
    insertion_sort(begin, std::size_t(end - begin));
  };
  if (n < 2) return;
  double first = keys[0].time, last = keys[0].time;
  for (const HitKey& k : keys) first = std::min(first, k.time), last = std::max(last, k.time);
  const double scale = double(n - 1) / (last - first);
  if (!(std::isfinite(scale) && scale > 0)) return sort_run(keys.data(), keys.data() + n);  // one time, or a span past double
  const auto bucket = [&](const HitKey& k) { return std::min(std::size_t((k.time - first) * scale), n - 1); };
  ends.assign(n + 1, 0);  // each bucket's first place, then (as keys go in) its end
  for (const HitKey& k : keys) ++ends[bucket(k) + 1];
  for (std::size_t b = 1; b <= n; ++b) ends[b] += ends[b - 1];
  scratch.resize(n);
  for (const HitKey& k : keys) scratch[ends[bucket(k)]++] = k;
  keys.swap(scratch);
  for (std::size_t b = 0, begin = 0; b < n; begin = ends[b++]) sort_run(keys.data() + begin, keys.data() + ends[b]);
}

template <class T>
void EventWatch<T>::scan(const EventCall<T>& call, const SliceEnds<T>& slice, double t0, double h) {
  if (slice.batches != nullptr) return scan_listed(call, slice, t0, h);
  scan_all(call, slice, t0, h);
}

// Every body of the slice (its own frame: the list of a block's bodies is large, and the
// listed batches' scan, which runs once a block, does not touch it).
template <class T>
void EventWatch<T>::scan_all(const EventCall<T>& call, const SliceEnds<T>& slice, double t0, double h) {
  if (slice.first >= call.size) return;
  const std::size_t real = std::min(slice.count, call.size - slice.first);
  // A slice is at most a block (the kernels' own test) and every body of it may cross.
  std::uint32_t found[std::max(kBlockBodies, kEventSliceBodies<T>)];
  for (std::size_t e = 0; e < events_.size(); ++e) {
    const std::size_t n = candidates(int(e), call, slice, real, t0, h, found);
    for (std::size_t k = 0; k < n && found[k] < real; ++k) locate(int(e), call, slice, found[k], t0, h);
  }
}

// Each batch the kernel's probe listed as a slice of its own, its start packed in `before`.
// The probe runs where every event is a built-in one: each batch takes the kernels' exact
// test straight from the table, the tests set once a call.
template <class T>
void EventWatch<T>::scan_listed(const EventCall<T>& call, const SliceEnds<T>& slice, double t0, double h) {
  const std::size_t width = call.table->width;
  std::array<kernels::EventScanJob<T>, kernels::kProbeTests> tests;
  std::copy(jobs_.begin(), jobs_.end(), tests.begin());
  std::uint32_t found[kMaxWidth];
  for (std::size_t k = 0; k < slice.batch_count; ++k) {
    SliceEnds<T> batch{{}, {}, slice.first + slice.batches[k], width};
    for (int a = 0; a < 6; ++a) batch.before[a] = slice.before[a] + k * width, batch.after[a] = slice.after[a] + slice.batches[k];
    const std::size_t real = std::min(width, call.size - std::min(call.size, batch.first));
    for (std::size_t e = 0; e < jobs_.size(); ++e) {
      kernels::EventScanJob<T>& test = tests[e];
      for (int a = 0; a < 6; ++a) test.before[a] = batch.before[a], test.after[a] = batch.after[a];
      const std::size_t n = call.table->event_scan[int(test.value)](test, width, found);
      for (std::size_t j = 0; j < n && found[j] < real; ++j) locate(int(e), call, batch, found[j], t0, h);
    }
  }
}

template <class T>
void EventWatch<T>::scan_blocks(const Workers& workers, const EventCall<T>& call, const T* const before[6],
                                const T* const after[6], std::size_t padded, double t0, double h) {
  for_each_block(workers, padded, [&](Block block) {
    for (std::size_t s = block.begin; s < block.end; s += kEventSliceBodies<T>) {
      SliceEnds<T> ends{{}, {}, s, std::min(kEventSliceBodies<T>, block.end - s)};
      for (int a = 0; a < 6; ++a) ends.before[a] = before[a] + s, ends.after[a] = after[a] + s;
      scan(call, ends, t0, h);
    }
  });
}

namespace {

// The built-in event's test over the slice's bodies.
template <class T>
std::size_t scan_slice(const kernels::KernelTable<T>& table, kernels::EventScanJob<T> job, const SliceEnds<T>& slice,
                       std::uint32_t* found) {
  for (int a = 0; a < 6; ++a) job.before[a] = slice.before[a], job.after[a] = slice.after[a];
  return table.event_scan[int(job.value)](job, slice.count, found);
}

}  // namespace

// The bodies of the slice whose value changed sign as the event asks: the kernel's test for
// the built-in values, the user's function at both ends otherwise.
template <class T>
std::size_t EventWatch<T>::candidates(int e, const EventCall<T>& call, const SliceEnds<T>& slice, std::size_t real,
                                      double t0, double h, std::uint32_t* found) const {
  const kernels::EventScanJob<T>& test = jobs_[e];
  const auto* fn = std::get_if<EventFunction<T>>(&events_[e].kind);
  if (fn == nullptr) return scan_slice(*call.table, test, slice, found);
  const auto view = [&](const T* const s[6], double t) {
    return EventBlock<T>{slice.first, real, t, s[0], s[1], s[2], s[3], s[4], s[5]};
  };
  // The values, then the kernels' test on them: whole SIMD batches, zeros past the real
  // bodies (a zero never counts as a crossing from zero).
  alignas(64) T g0[kEventSliceBodies<T>], g1[kEventSliceBodies<T>];
  (*fn)(view(slice.before, t0), g0);
  (*fn)(view(slice.after, t0 + h), g1);
  check_given(e, g0, real, slice.first, t0);
  check_given(e, g1, real, slice.first, t0 + h);
  const std::size_t batched = (real + call.table->width - 1) / call.table->width * call.table->width;
  std::fill(g0 + real, g0 + batched, T(0));
  std::fill(g1 + real, g1 + batched, T(0));
  kernels::EventScanJob<T> given = test;
  given.value = kernels::EventValue::given;
  given.before[0] = g0, given.after[0] = g1;
  return call.table->event_scan[int(kernels::EventValue::given)](given, batched, found);
}

namespace {

// The accelerations of the SIMD group whose first body is `body0`, its state at `state` (six
// arrays from the group's first body), through the stage kernel (the staged path's stage 0:
// the same terms the steps use).
template <class T>
void group_accelerations(const EventCall<T>& call, const T* const state[6], std::size_t body0,
                         T (&acc)[3][kMaxWidth]) {
  kernels::StageJob<T> job{};
  for (int d = 0; d < 3; ++d) job.x.in[d] = state[d], job.v.in[d] = state[3 + d], job.acc[d] = acc[d];
  job.accel_scale = 1;
  job.inv_mass = call.inv_mass + body0;
  job.per_body = call.per_body.from(body0);
  job.forces = call.forces;
  call.table->stage[call.forces.has_quadratic()][call.forces.has_central()](job, 0, call.table->width);
}

// The accelerations of that group at both ends of the step, as group_accelerations gives them.
template <class T>
void end_accelerations(const EventCall<T>& call, const T* const before[6], const T* const after[6], std::size_t body0,
                       T (&a0)[3][kMaxWidth], T (&a1)[3][kMaxWidth]) {
  kernels::EndsJob<T> job;
  job.forces = &call.forces;
  for (int d = 0; d < 3; ++d) {
    job.x[0][d] = before[d], job.v[0][d] = before[3 + d], job.acc[0][d] = a0[d];
    job.x[1][d] = after[d], job.v[1][d] = after[3 + d], job.acc[1][d] = a1[d];
  }
  job.inv_mass = call.inv_mass + body0;
  job.per_body = call.per_body.from(body0);
  call.table->end_accelerations[call.forces.has_quadratic()][call.forces.has_central()](job);
}

// dopri5's own term h sum_j d_j k_j for every lane of a SIMD group: its five inner stages
// taken again from the step's start, each state formed in double as DenseOutput forms it.
struct GroupTerms {
  double x[3][kMaxWidth], v[3][kMaxWidth];
};
template <class T>
GroupTerms dopri5_terms(const EventCall<T>& call, const T* const start[6], const T* const end[6],
                        const T* const a0[3], const T* const a1[3], std::size_t body0, double h) {
  const ButcherTableau& tab = dopri5.tableau;
  const std::size_t width = call.table->width;
  alignas(64) T kx[6][3][kMaxWidth], kv[6][3][kMaxWidth], state[6][kMaxWidth];
  for (int d = 0; d < 3; ++d) std::copy(start[3 + d], start[3 + d] + width, kx[0][d]), std::copy(a0[d], a0[d] + width, kv[0][d]);
  const T* const stage[6] = {state[0], state[1], state[2], state[3], state[4], state[5]};
  for (int s = 1; s < 6; ++s) {
    for (int d = 0; d < 3; ++d) {
      for (std::size_t l = 0; l < width; ++l) {
        double x = start[d][l], v = start[3 + d][l];
        for (int j = 0; j < s; ++j) x += h * tab.a[s][j] * kx[j][d][l], v += h * tab.a[s][j] * kv[j][d][l];
        state[d][l] = T(x), state[3 + d][l] = T(v), kx[s][d][l] = T(v);
      }
    }
    group_accelerations(call, stage, body0, kv[s]);
  }
  GroupTerms r;
  for (int d = 0; d < 3; ++d) {
    for (std::size_t l = 0; l < width; ++l) {
      double rx = kDopri5Dense[6] * end[3 + d][l], rv = kDopri5Dense[6] * a1[d][l];
      for (int j = 0; j < 6; ++j) rx += kDopri5Dense[j] * kx[j][d][l], rv += kDopri5Dense[j] * kv[j][d][l];
      r.x[d][l] = h * rx, r.v[d][l] = h * rv;
    }
  }
  return r;
}

template <class T>
StepEnds ends_of(const EventCall<T>& call, const SliceEnds<T>& slice, std::size_t local, double h) {
  const std::size_t lane = local % call.table->width, group = local - lane, body0 = slice.first + group;
  const T* before[6];
  const T* after[6];
  for (int a = 0; a < 6; ++a) before[a] = slice.before[a] + group, after[a] = slice.after[a] + group;
  alignas(64) T a0[3][kMaxWidth], a1[3][kMaxWidth];
  end_accelerations(call, before, after, body0, a0, a1);
  StepEnds e;
  e.h = h;
  for (int d = 0; d < 3; ++d) {
    e.x0[d] = double(before[d][lane]), e.v0[d] = double(before[3 + d][lane]), e.a0[d] = double(a0[d][lane]);
    e.x1[d] = double(after[d][lane]), e.v1[d] = double(after[3 + d][lane]), e.a1[d] = double(a1[d][lane]);
  }
  if (call.dopri5) {
    const T* const acc0[3] = {a0[0], a0[1], a0[2]};
    const T* const acc1[3] = {a1[0], a1[1], a1[2]};
    const GroupTerms r = dopri5_terms(call, before, after, acc0, acc1, body0, h);
    for (int d = 0; d < 3; ++d) e.rx[d] = r.x[d][lane], e.rv[d] = r.v[d][lane];
  }
  return e;
}

template <class T>
Vec3<T> narrow(const Vec& v) {
  return {T(v[0]), T(v[1]), T(v[2])};
}

}  // namespace

namespace {

// A body's positions (from x, v) or velocities (from v, a) over the step, as curves.
struct Curves {
  Curve y[3];
  static Curves positions(const StepEnds& e) {
    Curves c;
    for (int d = 0; d < 3; ++d) c.y[d] = Curve::of(e.x0[d], e.v0[d], e.x1[d], e.v1[d], e.h, e.rx[d]);
    return c;
  }
  static Curves velocities(const StepEnds& e) {
    Curves c;
    for (int d = 0; d < 3; ++d) c.y[d] = Curve::of(e.v0[d], e.a0[d], e.v1[d], e.a1[d], e.h, e.rv[d]);
    return c;
  }
};

// A plane's value n . x(theta) - offset and its slope, the zero components of n left out
// (each would add a zero: the same sums, a third of the work on an axis).
class PlaneValue {
 public:
  PlaneValue(const PlaneEvent& plane, const StepEnds& e) : offset_(plane.offset) {
    for (int d = 0; d < 3; ++d) {
      if (plane.normal[d] == 0) continue;
      x_[count_] = Curve::of(e.x0[d], e.v0[d], e.x1[d], e.v1[d], e.h, e.rx[d]);
      normal_[count_++] = plane.normal[d];
    }
  }
  Sample operator()(double theta) const {
    double value = 0, slope = 0;
    for (int k = 0; k < count_; ++k) value += normal_[k] * x_[k].at(theta), slope += normal_[k] * x_[k].slope(theta);
    return {value - offset_, slope};
  }

 private:
  Curve x_[3];
  double normal_[3];
  int count_ = 0;
  double offset_;
};

// |y(theta) - p|^2 - r2 and its slope.
Sample squared_distance(const Curves& y, const Vec& p, double r2, double theta) {
  double sum = 0, slope = 0;
  for (int d = 0; d < 3; ++d) {
    const double offset = y.y[d].at(theta) - p[d];
    sum += offset * offset, slope += 2 * offset * y.y[d].slope(theta);
  }
  return {sum - r2, slope};
}

// The fraction of the step at which the body's value of event e crosses: the built-in values
// with their slopes on the curves they read (formed once), a user's function on the state in
// T (no slope; NaN refused).
template <class T>
double crossing_of(const Event<T>& event, int e, const StepEnds& ends, std::size_t body, double t0, double tolerance) {
  if (const auto* plane = std::get_if<PlaneEvent>(&event.kind)) return crossing_fraction(PlaneValue(*plane, ends), tolerance);
  if (const auto* distance = std::get_if<DistanceEvent>(&event.kind)) {
    const Curves x = Curves::positions(ends);
    const double r2 = distance->radius * distance->radius;
    return crossing_fraction([&](double f) { return squared_distance(x, distance->point, r2, f); }, tolerance);
  }
  if (const auto* speed = std::get_if<SpeedEvent>(&event.kind)) {
    const Curves v = Curves::velocities(ends);
    const double s2 = speed->speed * speed->speed;
    return crossing_fraction([&](double f) { return squared_distance(v, Vec{}, s2, f); }, tolerance);
  }
  const auto& fn = std::get<EventFunction<T>>(event.kind);
  return crossing_fraction([&](double f) {
    const Vec3<T> xt = narrow<T>(dense_position(ends, f)), vt = narrow<T>(dense_velocity(ends, f));
    const EventBlock<T> one{body, 1, t0 + f * ends.h, &xt[0], &xt[1], &xt[2], &vt[0], &vt[1], &vt[2]};
    T g = 0;
    fn(one, &g);
    if (std::isnan(g)) check_given(e, &g, 1, body, t0 + f * ends.h);
    return Sample{double(g), std::numeric_limits<double>::quiet_NaN()};
  }, tolerance);
}

}  // namespace

template <class T>
void EventWatch<T>::locate(int e, const EventCall<T>& call, const SliceEnds<T>& slice, std::size_t local, double t0,
                           double h) {
  const StepEnds ends = ends_of(call, slice, local, h);
  const std::size_t body = slice.first + local;
  const double theta = crossing_of(events_[e], e, ends, body, t0, tolerance_ / h);
  if (found_at_settle(body, e, t0, theta, ends)) return;
  EventHit<T> hit{t0 + theta * h, body, e, narrow<T>(dense_position(ends, theta)),
                  narrow<T>(dense_velocity(ends, theta))};
  std::lock_guard lock(mutex_);
  hits_.push_back(hit);
  const bool earlier = !stop_ || hit.time < stop_->time || (hit.time == stop_->time && body < stop_->body);
  if (events_[e].action == EventAction::stop && earlier) stop_ = Stop{hit.time, theta, body, e};
}

template <class T>
void EventWatch<T>::remember_settled(const Stop& stop, double h, const T* const* state) {
  settled_ = stop;
  settled_hits_.clear();
  const double window = std::sqrt(std::numeric_limits<T>::epsilon()) * h;
  for (const EventHit<T>& hit : hits_) {
    if (hit.time > stop.time || hit.time < stop.time - window) continue;
    SettledHit s{hit.body, hit.event, {}};
    for (int d = 0; d < 3; ++d) s.position[d] = state[d][hit.body];
    settled_hits_.push_back(s);
  }
  std::sort(settled_hits_.begin(), settled_hits_.end());
}

// A crossing a stop left the set at, found again at the next call's start where the body's
// state in T lies a rounding short of it: the same crossing, reported already, not a new one,
// if the body starts the step where it was settled (a velocity changed since still meets it).
template <class T>
bool EventWatch<T>::found_at_settle(std::size_t body, int e, double t0, double theta, const StepEnds& ends) const {
  if (!settled_ || settled_->time != t0 || theta > std::sqrt(std::numeric_limits<T>::epsilon())) return false;
  const auto at = std::lower_bound(settled_hits_.begin(), settled_hits_.end(), SettledHit{body, e, {}});
  if (at == settled_hits_.end() || at->body != body || at->event != e) return false;
  for (int d = 0; d < 3; ++d) {
    if (double(at->position[d]) != ends.x0[d]) return false;
  }
  return true;
}

template <class T>
void EventWatch<T>::settle(const Workers& workers, ParticleSet<T>& b, const EventCall<T>& call,
                           const T* const before[6], const Stop& stop, double h) {
  const double theta = stop.theta;
  const std::size_t n = b.padded_size();
  for (auto& a : acc_) {
    if (a.size() < n) a = AlignedArray<T>(b.capacity());
  }
  T* const state[6] = {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()};
  const HermiteWeights w = HermiteWeights::at(theta);
  const double own = dopri5_weight(theta);
  // dopri5's term of a group, from the accelerations at both ends in acc_.
  const auto dopri5_group_terms = [&](const EventCall<T>& c, const T* const start[6], T* const end[6],
                                      std::size_t group, double step) {
    const T* s0[6];
    const T* s1[6];
    for (int a = 0; a < 6; ++a) s0[a] = start[a] + group, s1[a] = end[a] + group;
    const T* const a0[3] = {acc_[0].data() + group, acc_[1].data() + group, acc_[2].data() + group};
    const T* const a1[3] = {acc_[3].data() + group, acc_[4].data() + group, acc_[5].data() + group};
    return dopri5_terms(c, s0, s1, a0, a1, group, step);
  };
  for_each_block(workers, n, [&](Block block) {
    for (int end = 0; end < 2; ++end) {
      kernels::StageJob<T> job{};
      for (int d = 0; d < 3; ++d) {
        job.x.in[d] = end == 0 ? before[d] : state[d];
        job.v.in[d] = end == 0 ? before[3 + d] : state[3 + d];
        job.acc[d] = acc_[3 * end + d].data();
      }
      job.accel_scale = 1;
      job.inv_mass = call.inv_mass;
      job.per_body = call.per_body;
      job.forces = call.forces;
      call.table->stage[call.forces.has_quadratic()][call.forces.has_central()](job, block.begin, block.end);
    }
    const std::size_t width = call.table->width, real_end = std::min(block.end, call.size);
    for (std::size_t group = block.begin; group < real_end; group += width) {
      GroupTerms r{};
      if (call.dopri5) r = dopri5_group_terms(call, before, state, group, h);
      for (std::size_t i = group; i < std::min(group + width, real_end); ++i) {
        for (int d = 0; d < 3; ++d) {
          double x = w.of(before[d][i], before[3 + d][i], state[d][i], state[3 + d][i], h);
          double v = w.of(before[3 + d][i], acc_[d][i], state[3 + d][i], acc_[3 + d][i], h);
          if (call.dopri5) x += own * r.x[d][i - group], v += own * r.v[d][i - group];
          state[d][i] = T(x), state[3 + d][i] = T(v);
        }
      }
    }
  });
  remember_settled(stop, h, state);  // last: a settle that throws leaves the one before
}

// The rates at the step's end, then at its start (the set put back there for the probe), then
// each real body at the stop on their Hermite.
template <class T>
void EventWatch<T>::settle(const Workers& workers, RigidBodySet<T>& b, RigidBlockPath<T>& probe, bool renormalize,
                           const T* const before[13], const Stop& stop, double t0, double h) {
  const StateArrays<T> set = state_arrays(b);
  T* const* const state = set.data.data();
  const std::size_t n = b.padded_size(), size = b.size();
  for (auto* arrays : {&end_state_, &end_rates_}) {
    for (auto& a : *arrays) {
      if (a.size() < n) a = AlignedArray<T>(b.centers().capacity());
    }
  }
  probe.reserve(n);
  const typename RigidBlockPath<T>::Call call{b, T(1), renormalize};
  probe.evaluate_rates(call, workers, t0 + h);
  for_each_block(workers, n, [&](Block k) {
    for (int c = 0; c < 13; ++c) {
      std::copy(state[c] + k.begin, state[c] + k.end, end_state_[c].data() + k.begin);
      std::copy(probe.rate_of(c) + k.begin, probe.rate_of(c) + k.end, end_rates_[c].data() + k.begin);
      std::copy(before[c] + k.begin, before[c] + k.end, state[c] + k.begin);
    }
  });
  probe.evaluate_rates(call, workers, t0);
  const HermiteWeights weights = HermiteWeights::at(stop.theta);
  for_each_block(workers, n, [&](Block k) {
    for (std::size_t i = k.begin; i < k.end; ++i) {
      double y[13];
      for (int c = 0; c < 13; ++c) {
        y[c] = i < size ? weights.of(state[c][i], probe.rate_of(c)[i], end_state_[c][i], end_rates_[c][i], h)
                        : double(end_state_[c][i]);  // padding as the step left it
      }
      const double norm = std::sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9]);
      if (i < size) for (int c = 6; c < 10; ++c) y[c] /= norm;
      for (int c = 0; c < 13; ++c) state[c][i] = T(y[c]);
    }
  });
  remember_settled(stop, h, state);  // last: a settle that throws leaves the one before
}

template <class T>
std::size_t EventWatch<T>::bytes() const {
  std::size_t n = 0;
  for (const auto& a : acc_) n += a.size() * sizeof(T);
  n += (order_.capacity() + merged_.capacity()) * sizeof(HitKey) + buckets_.capacity() * sizeof(std::size_t) +
       sorted_.capacity() * sizeof(EventHit<T>);
  for (const auto* arrays : {&end_state_, &end_rates_}) {
    for (const auto& a : *arrays) n += a.size() * sizeof(T);
  }
  return n;
}

template class EventWatch<float>;
template class EventWatch<double>;

}  // namespace kinema
