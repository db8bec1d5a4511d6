// Events located inside a step on the dense output: crossing times against closed forms,
// their order of accuracy, each crossing found once, the stop action, the same list
// everywhere, and the events refused.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <tuple>

#include <xmmintrin.h>

#include "support.hpp"
#include "thread_pool.hpp"

using namespace kinema;

namespace {

constexpr double kG = 9.81;

Event<double> floor_event(EventAction action = EventAction::record) {
  return {PlaneEvent{{0, 1, 0}, 0}, Crossing::down, action};
}

// y0 + v0 t - g t^2 / 2 = 0, the later root.
double landing_time(double y0, double v0) { return (v0 + std::sqrt(v0 * v0 + 2 * kG * y0)) / kG; }

ForceModel<double> falling() {
  ForceModel<double> f;
  f.add(Gravity{{0, -kG, 0}});
  return f;
}

// Linear drag k under gravity: y(t) = y0 + u t + (v0 - u)(1 - e^-kt) / k, u = -g / k.
double drag_height(double y0, double v0, double k, double t) {
  const double u = -kG / k;
  return y0 + u * t + (v0 - u) * (1 - std::exp(-k * t)) / k;
}
double drag_landing(double y0, double v0, double k) {
  double t = landing_time(y0, v0);
  for (int i = 0; i < 50; ++i) {
    const double u = -kG / k, rate = u + (v0 - u) * std::exp(-k * t);
    t -= drag_height(y0, v0, k, t) / rate;
  }
  return t;
}

double drag_crossing_error(double h, const Method& method = rk4) {
  const double y0 = 10, v0 = 3, k = 0.8;
  ForceModel<double> f = falling();
  f.add(LinearDrag{k});
  Stepper<double> s(f, method, test::serial_options());
  s.set_events({{floor_event()}});
  ParticleSet<double> b;
  b.add({0, y0, 0}, {0, v0, 0}, 1);
  s.advance(b, h, std::uint64_t(std::ceil(4 / h)));
  REQUIRE(s.event_hits().size() == 1);
  return std::abs(s.event_hits()[0].time - drag_landing(y0, v0, k));
}

// Kepler's equation M = E - e sin E for an orbit of a = 1, mu = 1 starting at periapsis:
// the times at which r = a (E = pi / 2 outward, 3 pi / 2 inward) in each period 2 pi.
std::vector<double> kepler_radius_times(double e, int orbits) {
  std::vector<double> times;
  for (int k = 0; k < orbits; ++k) {
    for (double E : {std::numbers::pi / 2, 3 * std::numbers::pi / 2}) {
      times.push_back(2 * std::numbers::pi * k + E - e * std::sin(E));
    }
  }
  return times;
}

struct KeplerRun {
  double radius_error = 0, periapsis_error = 0;
  std::size_t radius_hits = 0, periapsis_hits = 0;
};

KeplerRun kepler_events(double e, double h, int orbits) {
  ForceModel<double> f;
  f.add(Central{{0, 0, 0}, 1});
  Stepper<double> s(f, rk4, test::serial_options());
  // Periapsis: the radial velocity x . v turns from negative to positive.
  const EventFunction<double> radial = [](const EventBlock<double>& b, double* value) {
    for (std::size_t i = 0; i < b.count; ++i) value[i] = b.px[i] * b.vx[i] + b.py[i] * b.vy[i] + b.pz[i] * b.vz[i];
  };
  s.set_events({{{DistanceEvent{{0, 0, 0}, 1}, Crossing::either}, {radial, Crossing::up}}});
  ParticleSet<double> b;
  b.add({1 - e, 0, 0}, {0, std::sqrt((1 + e) / (1 - e)), 0}, 1);
  const auto steps = std::uint64_t(std::llround((orbits + 0.1) * 2 * std::numbers::pi / h));  // past the last passage
  s.advance(b, h, steps);
  const std::vector<double> radius_times = kepler_radius_times(e, orbits);
  KeplerRun run;
  for (const EventHit<double>& hit : s.event_hits()) {
    if (hit.event == 0) {
      if (run.radius_hits < radius_times.size()) {
        run.radius_error = std::max(run.radius_error, std::abs(hit.time - radius_times[run.radius_hits]));
      }
      ++run.radius_hits;
    } else {
      const double passage = 2 * std::numbers::pi * double(run.periapsis_hits + 1);
      run.periapsis_error = std::max(run.periapsis_error, std::abs(hit.time - passage));
      ++run.periapsis_hits;
    }
  }
  return run;
}

// Mixes every field of the hits into h (FNV-1a); returns how many there were.
std::size_t hash_hits(std::uint64_t& h, const std::vector<EventHit<float>>& hits) {
  for (const EventHit<float>& hit : hits) {
    const double values[] = {hit.time, double(hit.body), double(hit.event), hit.position[0], hit.position[1],
                             hit.position[2], hit.velocity[0], hit.velocity[1], hit.velocity[2]};
    for (double v : values) h = (h ^ std::hash<double>{}(v)) * 1099511628211ull;
  }
  return hits.size();
}

}  // namespace

TEST_CASE("a projectile's floor crossing is found to round-off under rk4 with a coarse step", "[events]") {
  const double y0 = 10, v0 = 3, h = 0.1;
  Stepper<double> s(falling(), rk4, test::serial_options());
  s.set_events({{floor_event()}});
  ParticleSet<double> b;
  b.add({1, y0, -2}, {0.5, v0, 0}, 2);
  s.advance(b, h, 30);
  REQUIRE(s.event_hits().size() == 1);
  const EventHit<double>& hit = s.event_hits()[0];
  const double t = landing_time(y0, v0);
  CHECK(hit.body == 0);
  CHECK(hit.event == 0);
  CHECK(std::abs(hit.time - t) <= 1e-12 * t);
  CHECK(std::abs(hit.position[1]) <= 1e-12 * y0);
  CHECK(hit.position[0] == Approx(1 + 0.5 * t).epsilon(1e-13));
  CHECK(hit.velocity[1] == Approx(v0 - kG * t).epsilon(1e-12));
  CHECK(s.time() == Approx(30 * h));  // record: the call goes on
}

TEST_CASE("a crossing under drag is located to rk4's fourth order", "[events]") {
  std::vector<double> hs{0.1, 0.05, 0.025}, errors;
  for (double h : hs) errors.push_back(drag_crossing_error(h));
  INFO("errors " << errors[0] << " " << errors[1] << " " << errors[2]);
  CHECK(test::fitted_order(hs, errors) == Approx(4).margin(0.5));
  CHECK(errors[2] < 1e-7);
}

TEST_CASE("under dopri5 a crossing is located on its own interpolant, to its fifth order", "[events]") {
  // The Hermite alone is of order 4 inside a step; dopri5's term lifts it to the method's order.
  std::vector<double> hs{0.2, 0.1, 0.05}, errors;
  for (double h : hs) errors.push_back(drag_crossing_error(h, dopri5));
  INFO("errors " << errors[0] << " " << errors[1] << " " << errors[2]);
  CHECK(test::fitted_order(hs, errors) == Approx(5).margin(0.5));
  CHECK(errors[2] < drag_crossing_error(0.05) / 20);  // far below rk4's at the same step
}

TEST_CASE("Kepler e = 0.6: radius crossings match Kepler's equation, periapsis passages the period",
          "[events]") {
  const double e = 0.6;
  const int orbits = 3;
  const KeplerRun coarse = kepler_events(e, 2 * std::numbers::pi / 800, orbits);
  const KeplerRun fine = kepler_events(e, 2 * std::numbers::pi / 1600, orbits);
  CHECK(coarse.radius_hits == 2 * orbits);
  CHECK(coarse.periapsis_hits == std::size_t(orbits));  // the start is a periapsis, not a crossing
  CHECK(fine.radius_hits == 2 * orbits);
  INFO("radius errors " << coarse.radius_error << " " << fine.radius_error << ", periapsis "
                        << coarse.periapsis_error << " " << fine.periapsis_error);
  CHECK(coarse.radius_error < 1e-6);
  CHECK(coarse.periapsis_error < 1e-5);
  // The error is rk4's own: halving h divides it by about 16.
  CHECK(coarse.radius_error / fine.radius_error == Approx(16).epsilon(0.35));
  CHECK(coarse.periapsis_error / fine.periapsis_error == Approx(16).epsilon(0.35));
}

TEST_CASE("every body falling through a plane is found once, at its analytic time", "[events]") {
  const std::size_t n = 5000;
  ParticleSet<float> b;
  for (std::size_t i = 0; i < n; ++i) {
    b.add({float(i % 13), 1 + float(i % 97) * 0.1f, 0}, {0, float(i % 11) - 5, 0.5f}, 1);
  }
  ForceModel<float> f;
  f.add(Gravity{{0, -kG, 0}});
  Stepper<float> s(f, rk4, test::serial_options());
  s.set_events({{{PlaneEvent{{0, 1, 0}, 0}, Crossing::either}}});
  std::vector<int> found(n, 0);
  double worst = 0;
  for (int call = 0; call < 22; ++call) {  // calls of 6 steps of 1/60 s: 2.2 s in all
    s.advance(b, 1.0f / 60, 6);
    double last = -1;
    for (const EventHit<float>& hit : s.event_hits()) {
      CHECK(hit.time >= last);  // in order
      last = hit.time;
      ++found[hit.body];
      const double y0 = double(1 + float(hit.body % 97) * 0.1f), v0 = double(hit.body % 11) - 5;
      worst = std::max(worst, std::abs(hit.time - landing_time(y0, v0)));
    }
  }
  CHECK(std::count(found.begin(), found.end(), 1) == std::ptrdiff_t(n));  // none missed, none twice
  INFO("worst time error " << worst);
  CHECK(worst < 2e-5);
}

TEST_CASE("hits come in order of time, body and event, however their times crowd", "[events]") {
  // A thousand bodies that cross two planes at one time, others spread over the steps, one
  // far ahead of the rest: on two workers, several steps a call, blocks found in any order.
  // The first plane is watched twice: each body's two hits on it tie on time and body.
  ParticleSet<double> b;
  for (std::size_t i = 0; i < 3 * kBlockBodies; ++i) {
    const double height = i % 3 == 0 ? 1.0 : 0.6 + double((i * 7919) % 1000) / 1000;
    b.add({double(i % 13), i == 5 ? 0.51 : height, 0}, {0, i == 5 ? -30.0 : -4.0, 0}, 1);
  }
  ForceModel<double> f;
  f.add(Gravity{{0, -kG, 0}});
  test::ThreadPool pool(2);
  StepperOptions o = test::serial_options();
  o.jobs = &pool, o.workers = WorkerChoice::all;
  Stepper<double> s(f, rk4, o);
  const Event<double> upper{PlaneEvent{{0, 1, 0}, 0.5}, Crossing::down};
  s.set_events({{upper, {PlaneEvent{{0, 1, 0}, 0}, Crossing::down}, upper}});
  s.advance(b, 0.05, 12);
  const auto& hits = s.event_hits();
  REQUIRE(hits.size() == 3 * b.size());  // each body through each plane once
  const auto key = [](const EventHit<double>& h) { return std::tuple(h.time, h.body, h.event); };
  for (std::size_t i = 1; i < hits.size(); ++i) CHECK(key(hits[i - 1]) < key(hits[i]));
  CHECK(hits.front().body == 5);
}

namespace {

// Every body of several blocks crossing in the same step: the kernels list whole blocks.
template <class T>
void check_all_land_together() {
  const std::size_t n = 3 * kBlockBodies + 5;
  ParticleSet<T> b;
  for (std::size_t i = 0; i < n; ++i) b.add({T(i % 13), T(1), T(0)}, {T(0), T(-4), T(0)}, T(1));
  ForceModel<T> f;
  f.add(Gravity{{0, -kG, 0}});
  Stepper<T> s(f, rk4, test::serial_options());
  s.set_events({{{PlaneEvent{{0, 1, 0}, 0}, Crossing::down}}});
  s.advance(b, T(0.05), 6);  // lands at 0.2 s, in the fourth step
  REQUIRE(s.event_hits().size() == n);
  for (std::size_t i = 0; i < n; ++i) {
    CHECK(s.event_hits()[i].body == i);  // one time for all: in body order
    CHECK(std::abs(s.event_hits()[i].time - landing_time(1, -4)) < (sizeof(T) == 4 ? 1e-5 : 1e-12));
  }
}

}  // namespace

TEST_CASE("a whole set crossing in one step is found body by body, none lost", "[events]") {
  check_all_land_together<float>();
  check_all_land_together<double>();
}

TEST_CASE("a stop event ends the call at its time, every body on the dense output there", "[events]") {
  const double h = 0.1;
  Stepper<double> s(falling(), rk4, test::serial_options());
  s.set_events({{floor_event(EventAction::stop), {SpeedEvent{100}, Crossing::up}}});
  ParticleSet<double> b;
  b.add({0, 10, 0}, {0, 3, 0}, 1);   // lands first
  b.add({4, 30, 1}, {1, -2, 0}, 1);  // still in the air then
  s.advance(b, h, 50);
  const double t = landing_time(10, 3);
  REQUIRE(s.stopped_at_event());
  REQUIRE(s.event_hits().size() == 1);
  CHECK(s.event_hits()[0].body == 0);
  CHECK(s.time() == s.event_hits()[0].time);
  CHECK(std::abs(s.time() - t) <= 1e-12 * t);
  CHECK(std::abs(b.position(0)[1]) <= 1e-12);
  // The other body, interpolated to the same time, is where the parabola puts it.
  CHECK(b.position(1)[0] == Approx(4 + t).epsilon(1e-13));
  CHECK(b.position(1)[1] == Approx(30 - 2 * t - kG * t * t / 2).epsilon(1e-12));
  CHECK(b.velocity(1)[1] == Approx(-2 - kG * t).epsilon(1e-12));
  // The next call goes on from there: body 1 lands at its own time.
  s.advance(b, h, 50);
  REQUIRE(s.stopped_at_event());
  CHECK(s.event_hits().back().body == 1);
  CHECK(s.time() == Approx(landing_time(30, -2)).epsilon(1e-12));
  s.advance(b, h, 5);  // nothing left to cross
  CHECK_FALSE(s.stopped_at_event());
  CHECK(s.event_hits().empty());
}

TEST_CASE("events give the same hits on every ISA, thread count and job system", "[events]") {
  const EventFunction<float> above_diagonal = [](const EventBlock<float>& b, float* value) {
    for (std::size_t i = 0; i < b.count; ++i) value[i] = b.px[i] - b.py[i];
  };
  const std::vector<Event<float>> built_in = {{PlaneEvent{{0.2, 1, -0.1}, -0.5}, Crossing::either},
                                              {DistanceEvent{{0.5, 0, 0}, 1.5}, Crossing::up},
                                              {SpeedEvent{2}, Crossing::down}};
  std::vector<Event<float>> with_user = built_in;
  with_user.push_back({above_diagonal, Crossing::either});
  // The full scan (a user function), the kernels' sign test, and its one-plane form.
  const std::vector<std::vector<Event<float>>> lists = {
      with_user, built_in, {{PlaneEvent{{0, 1, 0}, -0.5}, Crossing::either}}};
  const auto hash = [&](StepperOptions o, std::size_t count) {
    std::uint64_t h = 1469598103934665603ull;
    for (const auto& events : lists) {
      ParticleSet<float> b = test::cloud<float>(count);
      Stepper<float> s(test::all_local_terms<float>(), rk4, o);
      s.set_events({events});
      std::size_t hits = 0;
      for (int call = 0; call < 4; ++call) {
        s.advance(b, 0.01f, 5);
        hits += hash_hits(h, s.event_hits());
      }
      CHECK(hits > count / 50);  // the test sees many hits
      h ^= test::state_hash(b);
    }
    return h;
  };
  test::check_same_bits_everywhere(hash, 512, 5000);
}

namespace {

// The hits of `events` on a cloud, with an extra user function that never crosses when
// `scanned` (which makes every slice store its start and be scanned whole).
std::vector<EventHit<float>> cloud_hits(const Method& method, std::vector<Event<float>> events, bool scanned,
                                        bool staged = false) {
  if (scanned) {
    events.push_back({EventFunction<float>([](const EventBlock<float>& b, float* value) {
                        std::fill(value, value + b.count, 1.0f);
                      }),
                      Crossing::either});
  }
  ParticleSet<float> b = test::cloud<float>(3000);
  StepperOptions o = test::serial_options();
  o.force_staged = staged;
  Stepper<float> s(test::all_local_terms<float>(), method, o);
  s.set_events({events});
  std::vector<EventHit<float>> hits;
  for (int call = 0; call < 4; ++call) {
    s.advance(b, 0.01f, 5);
    hits.insert(hits.end(), s.event_hits().begin(), s.event_hits().end());
  }
  return hits;
}

bool same_hit(const EventHit<float>& a, const EventHit<float>& b) {
  return a.time == b.time && a.body == b.body && a.event == b.event && a.position == b.position &&
         a.velocity == b.velocity;
}

}  // namespace

TEST_CASE("the fused kernels' own sign test finds exactly the crossings a full scan finds", "[events]") {
  const Event<float> floor{PlaneEvent{{0, 1, 0}, -0.5}, Crossing::either};  // along an axis: one array
  const Event<float> wall{PlaneEvent{{-1, 0, 0}, 0.25}, Crossing::up};
  const std::vector<std::vector<Event<float>>> lists = {
      {floor},
      {wall},
      {{PlaneEvent{{0.2, 1, -0.1}, -0.5}, Crossing::either},
       {DistanceEvent{{0.5, 0, 0}, 1.5}, Crossing::up},
       {SpeedEvent{2}, Crossing::down}},
      {floor, wall, floor, wall, {SpeedEvent{2}, Crossing::either}}};  // more than the kernels test
  for (const Method* method : {&rk4, &velocity_verlet, &euler}) {
    for (const auto& events : lists) {
      INFO(method->name << ", " << events.size() << " events");
      const auto probed = cloud_hits(*method, events, false), scanned = cloud_hits(*method, events, true);
      REQUIRE(probed.size() > 10);  // the scene crosses
      REQUIRE(probed.size() == scanned.size());  // the function never crosses
      CHECK(std::equal(probed.begin(), probed.end(), scanned.begin(), same_hit));
      // The staged path steps the same bits and scans each step whole.
      const auto staged = cloud_hits(*method, events, false, true);
      REQUIRE(staged.size() == probed.size());
      CHECK(std::equal(probed.begin(), probed.end(), staged.begin(), same_hit));
    }
  }
}

namespace {

// The hits of the fused kernels' own test of a plane along y (normal (0, a, 0), offset b)
// against those of a full scan, on every ISA, for bodies `start` over two steps of 1: either
// way, and each way alone (the kernels test a crossing one way with other compares).
template <class T>
void check_plane_hits(T a, T b, Crossing way, const ParticleSet<T>& start, std::size_t expected_at_least) {
  INFO("a " << a << ", b " << b << (sizeof(T) == 4 ? " float" : " double") << ", way " << int(way));
  const Event<T> plane{PlaneEvent{{0, double(a), 0}, double(b)}, way};
  const Event<T> never{EventFunction<T>([](const EventBlock<T>& v, T* value) { std::fill(value, value + v.count, T(1)); }),
                       Crossing::either};
  auto hits = [&](Isa isa, bool scanned) {
    ParticleSet<T> bodies = start;
    Stepper<T> s(ForceModel<T>{}, rk4, test::serial_options(isa));
    s.set_events({scanned ? std::vector<Event<T>>{plane, never} : std::vector<Event<T>>{plane}});
    s.advance(bodies, T(1), 2);
    return s.event_hits();
  };
  const auto scanned = hits(Isa::scalar, true);
  REQUIRE(scanned.size() >= expected_at_least);
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    INFO("isa " << isa_name(isa));
    const auto probed = hits(isa, false);
    REQUIRE(probed.size() == scanned.size());
    for (std::size_t i = 0; i < probed.size(); ++i) {
      CHECK(probed[i].body == scanned[i].body);
      CHECK(probed[i].time == scanned[i].time);
    }
  }
}

template <class T>
void check_plane_hits(T a, T b, const ParticleSet<T>& start, std::size_t expected_at_least) {
  for (Crossing way : {Crossing::either, Crossing::down, Crossing::up}) {
    const std::size_t least = way == Crossing::either ? expected_at_least : expected_at_least / 3;
    check_plane_hits(a, b, way, start, least);
  }
}

// Bodies that start a few steps to either side of b / a and move by a few steps a step: where
// the rounded value a y - b is 0 or turns sign. A step is an ulp of y, or where a is so short
// that the product's own underflow is coarser, the y that moves the product by a subnormal.
// And bodies that leap from far on one side to far on the other in one step, each way.
template <class T>
void check_plane_edges(T a, T b, std::size_t expected_at_least) {
  const T coarse = T(2 * double(std::numeric_limits<T>::denorm_min()) / std::abs(double(a)));
  const auto step = [&](T y) { return std::max(std::nextafter(std::abs(y), std::numeric_limits<T>::infinity()) - std::abs(y), coarse); };
  ParticleSet<T> start;
  const T centre = T(double(b) / double(a));
  T y = centre;
  for (int k = 0; k < 40; ++k) y -= step(y);
  for (int k = 0; k < 80; ++k, y += step(y)) {
    for (const T steps : {T(-3), T(-1), T(1), T(3)}) start.add({T(k % 7), y, T(0)}, {T(0), steps * step(y), T(0)}, T(1));
  }
  const T far = std::max(std::abs(centre) / 64, T(1));
  for (const T side : {T(-1), T(1)}) start.add({T(0), centre + side * far, T(0)}, {T(0), -side * 2 * far, T(0)}, T(1));
  check_plane_hits(a, b, start, expected_at_least);
}

// The host's flush to zero of results and inputs (FTZ, DAZ) on this thread, until the scope ends.
struct FlushToZero {
  unsigned saved = _mm_getcsr();
  FlushToZero() { _mm_setcsr(saved | 0x8040u); }
  ~FlushToZero() { _mm_setcsr(saved); }
};

}  // namespace

TEST_CASE("the fused kernels' test of a plane along an axis misses no crossing a rounding away from it", "[events]") {
  check_plane_edges<float>(1, 0, 12);
  check_plane_edges<float>(-3, 0.7f, 12);
  check_plane_edges<float>(2.5f, -1e-20f, 12);
  check_plane_edges<float>(1, 1e-41f, 12);  // b subnormal
  check_plane_edges<float>(0x1.31f49cp-57f, -0x1.ecp-142f, 12);  // products that underflow
  check_plane_edges<double>(-3, 0.7, 12);
  check_plane_edges<double>(7, 1e300, 12);
}

TEST_CASE("the fused kernels' test of a plane along an axis misses none where the host flushes to zero", "[events]") {
  const FlushToZero flush;
  // Bodies from a few smallest normals above and below a plane through 0 whose normal is
  // shorter than 1: a product under the smallest normal is 0, a crossing where it lands.
  ParticleSet<float> start;
  const float least = std::numeric_limits<float>::min();
  for (int k = -6; k <= 6; ++k) {
    for (int j = -8; j <= 8; ++j) start.add({float(k), float(k) * least, 0}, {0, float(j) * least / 4, 0}, 1);
  }
  check_plane_hits(0.891f, 0.0f, start, 12);
  check_plane_hits(0.25f, 0.0f, start, 12);
  check_plane_hits(-0.5f, 0.0f, start, 12);
}

namespace {

ForceModel<double> callback_model() {
  ForceModel<double> f = falling();
  f.add(ForceCallback<double>([](const ParticleBlock<double>&) {}));
  return f;
}

}  // namespace

TEST_CASE("advance_to watches events on its own steps: crossings to its tolerance, a stop ends the call there",
          "[events][adaptive]") {
  // Bodies under gravity and drag from different heights: each lands once, at its own time.
  const double k = 0.8;
  ForceModel<double> f = falling();
  f.add(LinearDrag{k});
  ParticleSet<double> b;
  for (int i = 0; i < 40; ++i) b.add({double(i), 2.0 + 0.5 * i, 0}, {0, 1.0 - 0.05 * i, 0}, 1);
  for (const Method* method : {&dopri5, &bs3}) {
    INFO(method->name);
    ParticleSet<double> run = b;
    Stepper<double> s(f, *method, test::serial_options());
    s.set_events({{floor_event()}});
    const Tolerances tol{1e-10, 1e-10};
    const AdaptiveStats stats = s.advance_to(run, 5, tol);
    REQUIRE(s.event_hits().size() == b.size());  // each body once, none twice
    double worst = 0;
    for (std::size_t i = 0; i < s.event_hits().size(); ++i) {
      const EventHit<double>& hit = s.event_hits()[i];
      if (i > 0) CHECK(hit.time >= s.event_hits()[i - 1].time);  // in order of time
      worst = std::max(worst, std::abs(hit.time - drag_landing(b.position(hit.body)[1], b.velocity(hit.body)[1], k)));
      CHECK(std::abs(hit.position[1]) < 1e-7);
    }
    INFO("steps " << stats.accepted << ", worst time error " << worst);
    // Located inside the steps the tolerance sized (dopri5 on its own interpolant, bs3 on the
    // Hermite), not at their ends.
    CHECK(worst < 1e-7);
  }
  // A stop: the call ends at the first landing, every body on the step's interpolant there.
  ParticleSet<double> run = b;
  Stepper<double> s(f, dopri5, test::serial_options());
  s.set_events({{floor_event(EventAction::stop)}});
  s.advance_to(run, 5, {1e-10, 1e-10});
  REQUIRE(s.stopped_at_event());
  REQUIRE(s.event_hits().size() == 1);
  const EventHit<double>& first = s.event_hits()[0];
  CHECK(first.body == 0);  // the lowest body lands first
  CHECK(s.time() == first.time);
  CHECK(std::abs(s.time() - drag_landing(2, 1, k)) < 1e-7);
  CHECK(std::abs(run.position(0)[1]) < 1e-7);
  CHECK(std::abs(run.position(5)[1] - drag_height(4.5, 0.75, k, s.time())) < 1e-7);
  // The next call goes on from there to the second landing, not the first again.
  s.advance_to(run, 5, {1e-10, 1e-10});
  REQUIRE(s.stopped_at_event());
  CHECK(s.event_hits()[0].body == 1);
  CHECK(std::abs(s.time() - drag_landing(2.5, 0.95, k)) < 1e-7);
  // A throwing event function takes back the step it was scanning: set and clock agree.
  ParticleSet<double> thrown = b;
  Stepper<double> t(f, dopri5, test::serial_options());
  t.set_events({{{EventFunction<double>([&](const EventBlock<double>& block, double* value) {
    if (block.t > 0.5) throw std::runtime_error("the game's event failed");
    for (std::size_t i = 0; i < block.count; ++i) value[i] = block.py[i];
  })}}});
  CHECK_THROWS_WITH(t.advance_to(thrown, 5, {1e-10, 1e-10}), "the game's event failed");
  CHECK(t.time() <= 0.5);
  CHECK(t.time() > 0.3);
  CHECK(std::abs(thrown.position(7)[1] - drag_height(5.5, 0.65, k, t.time())) < 1e-8);
  // The step taken back keeps none of its hits: not the stop the floor found before the throw.
  const double landing = drag_landing(2, 1, k);
  ParticleSet<double> again = b;
  Stepper<double> u(f, dopri5, test::serial_options());
  u.set_events({{floor_event(EventAction::stop), {EventFunction<double>([&](const EventBlock<double>& block, double* value) {
                   if (block.t > landing) throw std::runtime_error("the game's event failed");
                   for (std::size_t i = 0; i < block.count; ++i) value[i] = 1;
                 })}}});
  CHECK_THROWS_WITH(u.advance_to(again, 5, {1e-10, 1e-10}), "the game's event failed");
  CHECK(u.time() < landing);
  CHECK(u.event_hits().empty());
  CHECK_FALSE(u.stopped_at_event());
}

TEST_CASE("events are refused where they cannot be watched, and checked when set", "[events]") {
  Stepper<double> s(falling(), rk4, test::serial_options());
  CHECK_THROWS_WITH(s.set_events({{{PlaneEvent{{0, 0, 0}, 0}}}}), Catch::Contains("events[0]") &&
                                                                      Catch::Contains("normal must not be zero"));
  CHECK_THROWS_WITH(s.set_events({{floor_event(), {DistanceEvent{{0, 0, 0}, 0}}}}),
                    Catch::Contains("events[1]") && Catch::Contains("radius"));
  CHECK_THROWS_WITH(s.set_events({{{SpeedEvent{-1}}}}), Catch::Contains("speed"));
  CHECK_THROWS_WITH(s.set_events({{{PlaneEvent{{1e308, 1e308, 0}, 0}}}}),
                    Catch::Contains("plane normal's squared length overflows double"));
  CHECK_THROWS_WITH(s.set_events({{{PlaneEvent{{0, 1e-300, 0}, 0}}}}),
                    Catch::Contains("plane normal's squared length underflows double"));
  CHECK_THROWS_WITH(Stepper<float>(ForceModel<float>{}, rk4, test::serial_options()).set_events({{{PlaneEvent{{1e30, 1e30, 0}, 0}}}}),
                    Catch::Contains("plane normal's squared length overflows float"));
  CHECK_THROWS_WITH(s.set_events({{{EventFunction<double>{}}}}), Catch::Contains("empty"));
  CHECK_THROWS_WITH(s.set_events({{floor_event()}, -1}), Catch::Contains("time_tolerance"));
  Event<double> unnamed = floor_event();
  unnamed.direction = Crossing(3);
  CHECK_THROWS_WITH(s.set_events({{floor_event(), unnamed}}), Catch::Contains("events[1]: direction has no value 3"));
  unnamed = floor_event();
  unnamed.action = EventAction(2);
  CHECK_THROWS_WITH(s.set_events({{unnamed}}), Catch::Contains("events[0]: action has no value 2"));
  // Values float cannot hold: each names its own field.
  Stepper<float> single(ForceModel<float>{}, rk4, test::serial_options());
  CHECK_THROWS_WITH(single.set_events({{{PlaneEvent{{0, 1, 0}, 1e300}}}}), Catch::Contains("plane offset overflows"));
  CHECK_THROWS_WITH(single.set_events({{{DistanceEvent{{0, 0, 0}, 1e30}}}}), Catch::Contains("distance radius squared"));
  CHECK_THROWS_WITH(single.set_events({{{SpeedEvent{1e30}}}}), Catch::Contains("speed squared overflows"));
  CHECK_THROWS_WITH(single.set_events({{{PlaneEvent{{0, 1e39, 0}, 0}}}}), Catch::Contains("plane normal's squared length overflows float"));
  CHECK_THROWS_WITH(single.set_events({{{DistanceEvent{{1e39, 0, 0}, 1}}}}), Catch::Contains("distance point overflows"));
  s.set_events({{floor_event()}});
  ParticleSet<double> b;
  b.add({0, 1, 0}, {0, 0, 0}, 1);
  Stepper<double> pair(falling(), dopri5, test::serial_options());
  pair.set_events({{floor_event()}});
  Stepper<double> pair_callback(callback_model(), dopri5, test::serial_options());
  pair_callback.set_events({{floor_event()}});
  CHECK_THROWS_WITH(pair_callback.advance_to(b, 1, Tolerances{}), Catch::Contains("local terms only"));
  const ForceModel<double> callback = callback_model();
  Stepper<double> block_path(callback, rk4, test::serial_options());
  block_path.set_events({{floor_event()}});
  CHECK_THROWS_WITH(block_path.step(b, 0.1), Catch::Contains("local terms only"));
  Stepper<double> staged_callback(callback, dopri5, test::serial_options());
  staged_callback.set_events({{floor_event()}});
  CHECK_THROWS_WITH(staged_callback.step(b, 0.1), Catch::Contains("staged path"));
  CHECK(b.position(0)[1] == 1);  // nothing moved
  pair.set_events({});
  pair.advance_to(b, 0.1, Tolerances{});  // an empty list watches nothing
  CHECK(b.position(0)[1] < 1);
}

namespace {

// A guarded stepper watching the floor, with a central attractor at (0, -50, 0): a body that
// starts on it takes a first step that is not finite.
Stepper<double> guarded_floor() {
  StepperOptions o = test::serial_options();
  o.guard = FiniteGuard::check;
  ForceModel<double> f = falling();
  f.add(Central{{0, -50, 0}, 1e30});
  Stepper<double> s(f, rk4, o);
  s.set_events({{floor_event()}});
  return s;
}

}  // namespace

TEST_CASE("under the finiteness guard a call taken again records its hits once", "[events][guard]") {
  Stepper<double> s = guarded_floor();
  ParticleSet<double> b;
  b.add({0, 0.05, 0}, {0, -1, 0}, 1);
  b.add({0, -50, 0}, {0, 0, 0}, 1);
  CHECK_THROWS_AS(s.advance(b, 0.1, 3), NonFiniteError);
  CHECK(s.event_hits().empty());  // the first step threw: nothing of it is kept
  CHECK(b.position(0)[1] == 0.05);
}

namespace {

// Steps a second at h, a dense output around each step; `at(dense, t)` at three times inside.
template <class Set, class Dense, class At>
void inside_steps(Stepper<double>& s, Set& b, Dense& dense, double h, At&& at) {
  for (int step = 0; step < int(std::llround(1 / h)); ++step) {
    dense.begin(s, b);
    s.step(b, h);
    dense.end(s, b);
    for (double theta : {0.25, 0.5, 0.8}) at(dense.start_time() + theta * h);
  }
}

}  // namespace

TEST_CASE("dense output is exact inside a projectile's step, of rk4's order under drag, of dopri5's with its own", "[events][dense]") {
  const auto run = [](double k, double h, const Method& method) {
    ForceModel<double> f = falling();
    if (k > 0) f.add(LinearDrag{k});
    Stepper<double> s(f, method, test::serial_options());
    ParticleSet<double> b;
    b.add({0, 10, 0}, {0, 3, 0}, 1);
    DenseOutput<double> dense;
    double worst = 0;
    inside_steps(s, b, dense, h, [&](double t) {
      double x[3], v[3];
      double* xp[3] = {&x[0], &x[1], &x[2]};
      double* vp[3] = {&v[0], &v[1], &v[2]};
      dense.state_at(t, xp, vp);
      const double y = k > 0 ? drag_height(10, 3, k, t) : 10 + 3 * t - kG * t * t / 2;
      worst = std::max(worst, std::abs(x[1] - y));
      const double u = -kG / k, rate = k > 0 ? u + (3 - u) * std::exp(-k * t) : 3 - kG * t;
      worst = std::max(worst, std::abs(v[1] - rate));
    });
    return worst;
  };
  CHECK(run(0, 0.1, rk4) < 1e-13);
  const double coarse = run(0.8, 0.1, rk4), fine = run(0.8, 0.05, rk4);
  INFO("errors " << coarse << " " << fine);
  CHECK(coarse < 1e-5);
  CHECK(coarse / fine == Approx(16).epsilon(0.4));
  // dopri5: its own interpolant, of the method's fifth order over the run; the Hermite of
  // the same steps would be of order 4.
  CHECK(run(0, 0.1, dopri5) < 1e-13);
  const double own_coarse = run(0.8, 0.2, dopri5), own_fine = run(0.8, 0.1, dopri5);
  INFO("dopri5 errors " << own_coarse << " " << own_fine);
  CHECK(std::log2(own_coarse / own_fine) == Approx(5).margin(0.5));
  CHECK(own_fine < coarse / 20);  // far below the Hermite's at the same step
  DenseOutput<double> unused;
  double x = 0, *p[3] = {&x, &x, &x};
  CHECK_THROWS_AS(unused.state_at(0, p, p), Error);
}

TEST_CASE("dense output refuses an end that does not close one step of the same set", "[events][dense]") {
  Stepper<double> s(falling(), rk4, test::serial_options());
  ParticleSet<double> b;
  b.add({0, 10, 0}, {0, 3, 0}, 1);
  DenseOutput<double> dense;
  ParticleSet<double> empty;
  CHECK_THROWS_WITH(dense.end(s, empty), "DenseOutput::end: call begin on the same set first");
  dense.begin(s, b);
  s.advance(b, 0.01, 100);
  CHECK_THROWS_WITH(dense.end(s, b), "DenseOutput::end: 100 steps since begin; begin and end bracket one step");
  dense.begin(s, b);
  b.add({1, 0, 0}, {0, 0, 0}, 1);
  s.step(b, 0.01);
  CHECK_THROWS_WITH(dense.end(s, b), "DenseOutput::end: the set has 2 bodies, 1 at begin");
  dense.begin(s, b);
  s.step(b, 0.01);
  CHECK_NOTHROW(dense.end(s, b));
  dense.begin(s, b);
  StepperClock back = s.clock();
  back.steps -= 2;  // the same origin and size, two steps back
  s.set_clock(back);
  CHECK_THROWS_WITH(dense.end(s, b), "DenseOutput::end: the clock was set back since begin");
  // A jump forward: one step after set_time(5) once spanned [begin's t, 5 + h].
  dense.begin(s, b);
  s.set_time(5);
  s.step(b, 0.01);
  CHECK_THROWS_WITH(dense.end(s, b), Catch::Contains("DenseOutput::end: the clock ends more than one step past begin"));
  dense.begin(s, b);
  s.step(b, 0.02);  // a new size moves the origin to begin's time: one step, accepted
  CHECK_NOTHROW(dense.end(s, b));
  RigidBodySet<double> r;
  r.add({});
  RigidDenseOutput<double> rigid;
  rigid.begin(s, r);
  s.advance(r, 0.01, 3);
  CHECK_THROWS_WITH(rigid.end(s, r), Catch::Contains("RigidDenseOutput::end: 3 steps since begin"));
}

TEST_CASE("dense output takes a hit's time that rounds past the step's end", "[events][dense]") {
  // Bodies that reach the floor exactly at a step's end: t0 + theta h can round an ulp past
  // the clock's end of the step, and state_at(hit.time) refused it.
  Stepper<double> s(falling(), rk4, test::serial_options());
  EventOptions<double> floor;
  floor.events.push_back({PlaneEvent{{0, 1, 0}, 0}});
  floor.time_tolerance = 0.05;  // the root finder's bracket may end on the step's end
  s.set_events(floor);
  ParticleSet<double> b;
  for (int k = 1; k <= 40; ++k) {
    const double t = 0.05 * k;  // lands at a step's end: y = 4.905 t^2 from rest
    b.add({double(k), 0.5 * 9.81 * t * t, 0}, {0, 0, 0}, 1);
  }
  DenseOutput<double> dense;
  std::vector<double> x(b.padded_size()), y(b.padded_size()), z(b.padded_size());
  double* const pos[3] = {x.data(), y.data(), z.data()};
  std::vector<double> vx(b.padded_size()), vy(b.padded_size()), vz(b.padded_size());
  double* const vel[3] = {vx.data(), vy.data(), vz.data()};
  std::size_t hits = 0;
  for (int step = 0; step < 45; ++step) {
    dense.begin(s, b);
    s.step(b, 0.05);
    dense.end(s, b);
    for (const EventHit<double>& hit : s.event_hits()) {
      ++hits;
      CHECK(hit.time <= s.time() + 4 * std::numeric_limits<double>::epsilon() * s.time());
      CHECK_NOTHROW(dense.state_at(hit.time, pos, vel));
      CHECK(y[hit.body] == Approx(hit.position[1]).margin(1e-9));
    }
  }
  CHECK(hits == 40);
  CHECK_THROWS_WITH(dense.state_at(s.time() + 1e-9, pos, vel), Catch::Contains("t must lie inside the last step"));
}

TEST_CASE("calls that stop again and again make progress: a crossing a stop settled at is not found twice",
          "[events]") {
  Stepper<float> s(ForceModel<float>{}, rk4, test::serial_options());
  s.set_events({{{DistanceEvent{{0, 0, 0}, 1}, Crossing::either, EventAction::stop}}});
  ParticleSet<float> b;
  for (std::size_t i = 0; i < 2000; ++i) {  // straight out through r = 1 along many directions
    const float a = 0.37f * float(i), c = 0.11f * float(i), r = 0.5f + 0.0002f * float(i);
    const Vec3<float> dir{std::cos(a) * std::cos(c), std::sin(a) * std::cos(c), std::sin(c)};
    b.add({r * dir[0], r * dir[1], r * dir[2]}, {0.3f * dir[0], 0.3f * dir[1], 0.3f * dir[2]}, 1);
  }
  s.set_time(1000);
  double last = s.time();
  std::size_t stops = 0;
  for (int call = 0; call < 2500 && s.time() < 1002; ++call) {
    const std::uint64_t taken = s.advance(b, 0.01f, 50, StopRequest{});
    INFO("call " << call << " at t = " << s.time());
    REQUIRE(s.time() > last);  // never stuck where the last call stopped
    last = s.time();
    if (s.stopped_at_event()) {
      ++stops;
      CHECK(taken >= 1);
      CHECK(taken <= 50);
    } else {
      CHECK(taken == 50);
    }
  }
  CHECK(stops > 10);
}

TEST_CASE("a body moved into a stopped body's place keeps its own crossing", "[events]") {
  // Two bodies land 2 us apart; the first stops the call and the game removes it: the last
  // body moves into its index. Its crossing, in the next step's first sqrt(eps) h, is its own.
  ForceModel<float> f;
  f.add(Gravity{{0, -10, 0}});
  for (const bool despawn : {false, true}) {
    INFO("despawn " << despawn);
    Stepper<float> s(f, rk4, test::serial_options());
    s.set_events({{{PlaneEvent{{0, 1, 0}, 0}, Crossing::down, EventAction::stop}}});
    ParticleSet<float> p;
    p.add({0, 5.0f, 0}, {0, 0, 0}, 1);     // lands at t = 1
    p.add({1, 5.00002f, 0}, {0, 0, 0}, 1);  // about 2e-6 s later
    std::vector<EventHit<float>> hits;
    for (int k = 0; k < 120; ++k) {
      s.step(p, 1.0f / 60);
      hits.insert(hits.end(), s.event_hits().begin(), s.event_hits().end());
      if (despawn && hits.size() == 1 && p.size() == 2) p.remove(0);
    }
    REQUIRE(hits.size() == 2);
    CHECK(hits[1].time > hits[0].time);
    CHECK(hits[1].position[0] == 1);  // the second body's own landing
    CHECK(hits[1].time - hits[0].time < 1e-5);
  }
}

TEST_CASE("a stopped body whose velocity the game changes is not reported landing again", "[events]") {
  // A settle can leave the body a rounding above the plane, where the next step finds its
  // crossing again at theta ~ 0: reported once, whatever its velocity became.
  ForceModel<float> f;
  f.add(Gravity{{0, -10, 0}});
  int above = 0;  // settles a rounding short of the plane: the case this is about
  for (int k = 0; k < 40; ++k) {
    Stepper<float> s(f, rk4, test::serial_options());
    s.set_events({{{PlaneEvent{{0, 1, 0}, 0}, Crossing::down, EventAction::stop}}});
    ParticleSet<float> p;
    p.add({0, 5.0f + 0.173f * float(k), 0}, {0, 0, 0}, 1);
    std::size_t hits = 0;
    for (int n = 0; n < 150; ++n) {
      s.step(p, 1.0f / 60);
      hits += s.event_hits().size();
      if (!s.stopped_at_event()) continue;
      above += p.py()[0] > 0;
      p.set_velocity(0, {0.1f, p.velocity(0)[1] * 1.01f, 0});  // wind, damping
    }
    CHECK(hits == 1);
  }
  CHECK(above > 0);
}

TEST_CASE("after a stop, no crossing reported at its time is found again: other bodies, other events",
          "[events]") {
  // Three bodies on one path, a record and a stop event on one plane: every one of the six
  // (body, event) crossings is reported once, and the call after the stop goes on from it.
  for (const Method* m : {&rk4, &rk6, &symplectic_euler, &bs3, &dopri5}) {
    INFO(m->name);
    Stepper<double> s(falling(), *m, test::serial_options());
    s.set_events({{floor_event(EventAction::record), floor_event(EventAction::stop)}});
    ParticleSet<double> b;
    for (int i = 0; i < 3; ++i) b.add({double(i), 10, 0}, {1, 5, 0}, 1);
    std::map<std::pair<std::size_t, int>, int> reported;
    double last = s.time();
    for (int call = 0; call < 6; ++call) {
      s.advance(b, 0.1, 10, StopRequest{});
      INFO("call " << call << " at t = " << s.time());
      CHECK(s.time() > last);
      last = s.time();
      for (const EventHit<double>& hit : s.event_hits()) ++reported[{hit.body, hit.event}];
    }
    CHECK(reported.size() == 6);
    for (const auto& [key, count] : reported) CHECK(count == 1);
  }
  // The same under error control, a call to each next second.
  Stepper<double> s(falling(), dopri5, test::serial_options());
  s.set_events({{floor_event(EventAction::record), floor_event(EventAction::stop)}});
  ParticleSet<double> b;
  for (int i = 0; i < 3; ++i) b.add({double(i), 10, 0}, {1, 5, 0}, 1);
  std::map<std::pair<std::size_t, int>, int> reported;
  for (int call = 0; call < 6; ++call) {
    const double before = s.time();
    s.advance_to(b, std::floor(before) + 1, Tolerances{1e-9, 1e-9});
    CHECK(s.time() > before);
    for (const EventHit<double>& hit : s.event_hits()) ++reported[{hit.body, hit.event}];
  }
  CHECK(reported.size() == 6);
  for (const auto& [key, count] : reported) CHECK(count == 1);
}

namespace {

// Ten steps of a set of several blocks whose event function throws on the third block's
// fourth call (earlier blocks have then taken every step): the set, the clock and the hits
// as before the call.
template <class Set>
void check_throwing_event_function(Set b, const ForceModel<double>& forces) {
  const std::uint64_t before = test::state_hash(b);
  Stepper<double> s(forces, rk4, test::serial_options());
  int calls = 0;
  s.set_events({{{EventFunction<double>([&](const EventBlock<double>& block, double* value) {
    if (block.first >= 2048 && ++calls > 3) throw std::runtime_error("the game's event failed");
    for (std::size_t i = 0; i < block.count; ++i) value[i] = block.py[i];
  })}}});
  CHECK_THROWS_WITH(s.advance(b, 0.01, 10), "the game's event failed");
  CHECK(test::state_hash(b) == before);
  CHECK(s.time() == 0);
  CHECK(s.event_hits().empty());
}

}  // namespace

TEST_CASE("a throwing event function leaves the set and the clock as before the call", "[events]") {
  check_throwing_event_function(test::cloud<double>(3000), test::all_local_terms<double>());
}

TEST_CASE("an event function's NaN is refused by name, the set and the clock as before the call", "[events]") {
  // +1 until t = 1.55, then NaN: no sign to cross with, at a step's end or inside one.
  ParticleSet<double> b;
  b.add({0, 10, 0}, {0, 0, 0}, 1);
  const std::uint64_t before = test::state_hash(b);
  Stepper<double> s(falling(), rk4, test::serial_options());
  s.set_events({{{EventFunction<double>([](const EventBlock<double>& block, double* value) {
                    for (std::size_t i = 0; i < block.count; ++i) value[i] = block.t < 1.55 ? 1 : std::nan("");
                  }),
                  Crossing::either}}});
  CHECK_THROWS_WITH(s.advance(b, 0.1, 30), Catch::Contains("events[0]: the event function gave NaN for body 0 at t = 1.6"));
  CHECK(test::state_hash(b) == before);
  CHECK(s.time() == 0);
  CHECK(s.event_hits().empty());
}

TEST_CASE("rigid dense output: a spinning body's orientation to rk4's order and of unit length, its centre exact",
          "[events][dense]") {
  // Free spin about the principal z axis at omega: q(t) = (cos(omega t / 2), 0, 0, sin(omega t / 2));
  // the centre falls under gravity (a parabola, on which the Hermite is exact).
  const double omega = 2;
  const auto run = [&](double h) {
    Stepper<double> s(falling(), rk4, test::serial_options());
    RigidBodySet<double> b;
    b.add({{0, 10, 0}, {1, 3, 0}, {1, 0, 0, 0}, {0, 0, omega * 0.5}, 2, {0.3, 0.4, 0.5}});
    RigidDenseOutput<double> dense;
    double worst_angle = 0, worst_centre = 0, worst_norm = 0;
    inside_steps(s, b, dense, h, [&](double t) {
      double x[3], v[3], q[4], l[3];
      double* xp[3] = {&x[0], &x[1], &x[2]};
      double* vp[3] = {&v[0], &v[1], &v[2]};
      double* qp[4] = {&q[0], &q[1], &q[2], &q[3]};
      double* lp[3] = {&l[0], &l[1], &l[2]};
      dense.state_at(t, xp, vp, qp, lp);
      worst_angle = std::max({worst_angle, std::abs(q[0] - std::cos(omega * t / 2)),
                              std::abs(q[3] - std::sin(omega * t / 2)), std::abs(q[1]), std::abs(q[2])});
      worst_norm = std::max(worst_norm, std::abs(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1));
      worst_centre = std::max({worst_centre, std::abs(x[0] - t), std::abs(x[1] - (10 + 3 * t - kG * t * t / 2)),
                               std::abs(v[1] - (3 - kG * t)), std::abs(l[2] - omega * 0.5)});
    });
    return std::array<double, 3>{worst_angle, worst_centre, worst_norm};
  };
  const auto coarse = run(0.1), fine = run(0.05);
  INFO("orientation errors " << coarse[0] << " " << fine[0]);
  CHECK(std::log2(coarse[0] / fine[0]) == Approx(4).margin(0.5));
  CHECK(coarse[0] < 1e-5);
  CHECK(coarse[1] < 1e-12);
  CHECK(coarse[2] < 1e-15);
  RigidDenseOutput<double> unused;
  double z = 0, *p[4] = {&z, &z, &z, &z};
  CHECK_THROWS_AS(unused.state_at(0, p, p, p, p), Error);
}

// Rigid bodies: events on their centres, the fused rigid kernels and the rigid path alike.

namespace {

RigidBodyDesc<double> spinning(const Vec3<double>& x, const Vec3<double>& v, double spin = 2) {
  return {x, v, {1, 0, 0, 0}, {0.1, -0.2, spin * 0.5}, 2, {0.3, 0.4, 0.5}};
}

}  // namespace

TEST_CASE("rigid bodies: a turning body's floor crossing is found to round-off with a coarse step, on each path",
          "[events]") {
  const double y0 = 10, v0 = 3, h = 0.1, t = landing_time(y0, v0);
  for (const Method* m : {&rk4, &velocity_verlet, &bs3, &dopri5}) {  // fused kernels; the rigid path
    INFO(m->name);
    Stepper<double> s(falling(), *m, test::serial_options());
    s.set_events({{floor_event()}});
    RigidBodySet<double> b;
    b.add(spinning({1, y0, -2}, {0.5, v0, 0}));
    s.advance(b, h, 30);
    REQUIRE(s.event_hits().size() == 1);
    const EventHit<double>& hit = s.event_hits()[0];
    CHECK(hit.body == 0);
    CHECK(std::abs(hit.time - t) <= 1e-12 * t);
    CHECK(std::abs(hit.position[1]) <= 1e-12 * y0);
    CHECK(hit.position[0] == Approx(1 + 0.5 * t).epsilon(1e-13));
    CHECK(hit.velocity[1] == Approx(v0 - kG * t).epsilon(1e-12));
    CHECK(s.time() == Approx(30 * h));
  }
}

TEST_CASE("rigid bodies: every body of several blocks through a plane is found once, at its analytic time",
          "[events]") {
  Stepper<double> s(falling(), rk4, test::serial_options());
  s.set_events({{floor_event()}});
  RigidBodySet<double> b;
  const std::size_t n = 2500;
  for (std::size_t i = 0; i < n; ++i) b.add(spinning({0, 1 + 0.01 * double(i), 0}, {0, 0, 0}, 0.001 * double(i)));
  std::vector<int> found(n, 0);
  double worst = 0;
  for (int call = 0; call < 12; ++call) {
    s.advance(b, 0.05, 5);
    for (const EventHit<double>& hit : s.event_hits()) {
      ++found[hit.body];
      worst = std::max(worst, std::abs(hit.time - landing_time(1 + 0.01 * double(hit.body), 0)));
    }
  }
  CHECK(std::count(found.begin(), found.end(), 1) == std::ptrdiff_t(n));  // every one, once
  CHECK(worst < 1e-12);
}

TEST_CASE("rigid bodies: a stop event settles every body's 13 components on the dense output, q of unit length",
          "[events]") {
  // Body 0 (mass 2) falls at g - 0.5 / 2: the point force pushes its centre up.
  const double h = 0.1, g0 = kG - 0.25, t = (3 + std::sqrt(9 + 2 * g0 * 10)) / g0;
  const auto bodies = [] {
    RigidBodySet<double> b;
    b.add({{0, 10, 0}, {0, 3, 0}, {1, 0, 0, 0}, {0, 0, 1}, 2, {0.3, 0.4, 0.5}});  // spins about z at 2 rad/s
    b.add({{4, 30, 1}, {1, -2, 0}, {0.9, 0.1, -0.3, 0.2}, {0.4, 0.7, -0.2}, 1, {1, 2, 2.5}});  // tumbles
    return b;
  };
  ForceModel<double> f = falling();
  f.add(AngularDrag{0.3}).add(PointForce{{0.2, 0, 0}, {0, 0.5, 0}});
  Stepper<double> s(f, rk4, test::serial_options());
  s.set_events({{floor_event(EventAction::stop)}});
  RigidBodySet<double> b = bodies();
  s.advance(b, h, 50);
  REQUIRE(s.stopped_at_event());
  REQUIRE(s.event_hits().size() == 1);
  CHECK(s.time() == s.event_hits()[0].time);
  CHECK(std::abs(s.event_hits()[0].position[1]) <= 1e-12);
  CHECK(std::abs(b.centers().position(0)[1]) <= 1e-12);
  // The same steps without events, and their dense output at the stop.
  Stepper<double> free(f, rk4, test::serial_options());
  RigidBodySet<double> reference = bodies();
  RigidDenseOutput<double> dense;
  while (free.time() + h < s.time()) free.step(reference, h);
  dense.begin(free, reference);
  free.step(reference, h);
  dense.end(free, reference);
  double cx[3][2], cv[3][2], cq[4][2], cl[3][2];
  double* cxp[3] = {cx[0], cx[1], cx[2]};
  double* cvp[3] = {cv[0], cv[1], cv[2]};
  double* cqp[4] = {cq[0], cq[1], cq[2], cq[3]};
  double* clp[3] = {cl[0], cl[1], cl[2]};
  dense.state_at(s.time(), cxp, cvp, cqp, clp);
  for (std::size_t i = 0; i < 2; ++i) {
    INFO("body " << i);
    const Quat<double> qi = b.orientation(i);
    double norm = 0;
    for (int k = 0; k < 4; ++k) {
      CHECK(qi[k] == Approx(cq[k][i]).margin(1e-13));
      norm += qi[k] * qi[k];
    }
    CHECK(std::abs(std::sqrt(norm) - 1) < 1e-15);
    for (int d = 0; d < 3; ++d) {
      CHECK(b.centers().position(i)[d] == Approx(cx[d][i]).margin(1e-12));
      CHECK(b.centers().velocity(i)[d] == Approx(cv[d][i]).margin(1e-12));
      CHECK(b.angular_momentum(i)[d] == Approx(cl[d][i]).margin(1e-13));
    }
  }
  CHECK(std::abs(s.time() - t) <= 1e-12 * t);
  // The next call goes on from there: body 1 lands at its own time.
  s.advance(b, h, 50);
  REQUIRE(s.stopped_at_event());
  CHECK(s.event_hits().back().body == 1);
}

TEST_CASE("rigid bodies: the same hits and stops on every ISA, thread count and job system", "[events]") {
  const EventFunction<float> above_diagonal = [](const EventBlock<float>& b, float* value) {
    for (std::size_t i = 0; i < b.count; ++i) value[i] = b.px[i] - b.py[i];
  };
  const std::vector<Event<float>> record = {{PlaneEvent{{0.2, 1, -0.1}, -0.5}, Crossing::either},
                                            {DistanceEvent{{0.5, 0, 0}, 1.5}, Crossing::up},
                                            {SpeedEvent{2}, Crossing::down},
                                            {above_diagonal, Crossing::either}};
  const std::vector<Event<float>> stop = {{PlaneEvent{{0, 1, 0}, -0.5}, Crossing::down, EventAction::stop}};
  const auto hash = [&](StepperOptions o, std::size_t count) {
    std::uint64_t h = 1469598103934665603ull;
    for (const Method* m : {&rk4, &bs3}) {
      for (const bool stops : {false, true}) {
        RigidBodySet<float> b = test::tumbling_cloud<float>(count);
        Stepper<float> s(test::rotational_terms<float>(), *m, o);
        s.set_events({stops ? stop : record});
        std::size_t hits = 0;
        for (int call = 0; call < 4; ++call) {
          s.advance(b, 0.01f, 5);
          hits += hash_hits(h, s.event_hits());
        }
        CHECK(hits >= (stops ? 4u : count / 50));
        h ^= test::state_hash(b) ^ std::hash<double>{}(s.time());
      }
    }
    return h;
  };
  test::check_same_bits_everywhere(hash, 512, 5000);
}

TEST_CASE("rigid bodies: events are refused where a centre does not move alone", "[events]") {
  RigidBodySet<double> b;
  b.add(spinning({0, 1, 0}, {0, 0, 0}));
  const auto refused = [&](ForceModel<double> f, const Method& m = rk4) {
    Stepper<double> s(std::move(f), m, test::serial_options());
    s.set_events({{floor_event()}});
    CHECK_THROWS_WITH(s.step(b, 0.1), Catch::Contains("rigid bodies") && Catch::Contains("local terms only"));
  };
  ForceModel<double> callback = falling();
  callback.add([](const RigidBlock<double>&) {});
  refused(callback);
  ForceModel<double> point_spring = falling();
  point_spring.add(PointSpring{{0.1, 0, 0}, {0, 2, 0}, 5});
  refused(point_spring);
  ForceModel<double> body_springs = falling();
  body_springs.add(BodySprings{{{0, 1, {0, 0, 0}, {0, 0, 0}, 1, 1}}});
  refused(body_springs, bs3);
  Stepper<double> pair(callback, dopri5, test::serial_options());
  pair.set_events({{floor_event()}});
  CHECK_THROWS_WITH(pair.advance_to(b, 1, Tolerances{}), Catch::Contains("local terms only"));
  CHECK(b.centers().position(0)[1] == 1);  // nothing moved
}

TEST_CASE("rigid bodies under the finiteness guard: a call taken back keeps none of its hits", "[events][guard]") {
  Stepper<double> s = guarded_floor();
  RigidBodySet<double> b;
  b.add(spinning({0, 0.05, 0}, {0, -1, 0}));
  b.add(spinning({0, -50, 0}, {0, 0, 0}));
  CHECK_THROWS_AS(s.advance(b, 0.1, 3), NonFiniteError);
  CHECK(s.event_hits().empty());
  CHECK(b.centers().position(0)[1] == 0.05);
  s.set_forces(falling());
  s.advance(b, 0.1, 3);
  CHECK(s.event_hits().size() == 1);
}

TEST_CASE("rigid bodies under advance_to: crossings on each accepted step, a stop settles the set there",
          "[events]") {
  const double t = landing_time(10, 3), later = landing_time(30, -2);
  Stepper<double> s(falling(), dopri5, test::serial_options());
  s.set_events({{floor_event()}});
  RigidBodySet<double> b;
  b.add(spinning({0, 10, 0}, {1, 3, 0}));
  b.add(spinning({4, 30, 1}, {0, -2, 0}, -1));
  s.advance_to(b, 5, Tolerances{1e-9, 1e-9});
  REQUIRE(s.event_hits().size() == 2);
  CHECK(std::abs(s.event_hits()[0].time - t) <= 1e-12 * t);
  CHECK(std::abs(s.event_hits()[1].time - later) <= 1e-12 * later);
  CHECK(s.time() == 5);
  s.set_events({{floor_event(EventAction::stop)}});
  RigidBodySet<double> again;
  again.add(spinning({0, 10, 0}, {1, 3, 0}));
  again.add({{4, 30, 1}, {0, -2, 0}, {1, 0, 0, 0}, {0, 0, 1}, 2, {0.3, 0.4, 0.5}});  // 2 rad/s about z
  s.set_time(0);
  s.advance_to(again, 5, Tolerances{1e-9, 1e-9});
  REQUIRE(s.stopped_at_event());
  CHECK(std::abs(s.time() - t) <= 1e-12 * t);
  CHECK(std::abs(again.centers().position(0)[1]) <= 1e-11);
  CHECK(again.centers().position(1)[1] == Approx(30 - 2 * t - kG * t * t / 2).epsilon(1e-12));
  // Body 1's q(t) = (cos t, 0, 0, sin t), on its step's Hermite at the stop.
  const Quat<double> q = again.orientation(1);
  CHECK(std::abs(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1) < 1e-15);
  CHECK(std::abs(q[0] - std::cos(t)) < 1e-6);
  CHECK(std::abs(q[3] - std::sin(t)) < 1e-6);
  CHECK(again.angular_momentum(1)[2] == 1);
  s.advance_to(again, 5, Tolerances{1e-9, 1e-9});  // goes on from there to the other landing
  REQUIRE(s.stopped_at_event());
  CHECK(std::abs(s.time() - later) <= 1e-12 * later);
}

TEST_CASE("rigid bodies: a stop under dopri5 with drag leaves the centre on the crossing it located", "[events]") {
  ForceModel<double> f = falling();
  f.add(LinearDrag{0.8});
  for (const bool adaptive : {false, true}) {
    INFO((adaptive ? "advance_to" : "fixed steps"));
    Stepper<double> s(f, dopri5, test::serial_options());
    s.set_events({{floor_event(EventAction::stop)}});
    RigidBodySet<double> b;
    b.add(spinning({0, 10, 0}, {1, 3, 0}));
    b.add(spinning({4, 30, 1}, {0, -2, 0}));
    adaptive ? void(s.advance_to(b, 6, Tolerances{1e-6, 1e-6})) : s.advance(b, 0.1, 60);
    REQUIRE(s.stopped_at_event());
    const EventHit<double> hit = s.event_hits()[0];
    CHECK(std::abs(b.centers().position(0)[1]) <= 1e-12);  // on the plane, where it was located
    CHECK(b.centers().position(0)[0] == hit.position[0]);
    CHECK(std::abs(hit.time - drag_landing(10, 3, 0.4)) < 1e-5);  // F = -0.8 v on a mass of 2
    const double stopped = s.time();
    adaptive ? void(s.advance_to(b, 6, Tolerances{1e-6, 1e-6})) : s.advance(b, 0.1, 60);
    REQUIRE(s.stopped_at_event());  // the next landing, not the same one again
    CHECK(s.event_hits()[0].body == 1);
    CHECK(s.time() > stopped + 0.5);
  }
}

TEST_CASE("rigid bodies: a throwing event function leaves the set and the clock as before the call", "[events]") {
  check_throwing_event_function(test::tumbling_cloud<double>(3000), test::rotational_terms<double>());
}
