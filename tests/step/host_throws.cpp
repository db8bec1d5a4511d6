// A host job system whose enqueue throws, as its contract allows before it takes a range
// (an engine's queue out of memory, say), at each enqueue of a call in turn and on every
// path: the set and the clock are left as before the step that threw, and the call can go
// on to the bits of a call that never threw.
#include <catch2/catch.hpp>

#include <algorithm>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <vector>

#include "support.hpp"

using namespace kinema;

namespace {

// Runs every job inline on the calling thread, and throws at its `throw_at`-th enqueue.
class ThrowingJobs final : public JobSystem {
 public:
  unsigned worker_count() const override { return 2; }
  JobHandle enqueue(RangeTask task, std::size_t count, std::size_t, void* context) override {
    ++calls;
    if (calls == throw_at || (keeps_failing && throw_at > 0 && calls > throw_at)) throw std::runtime_error("enqueue failed");
    task(0, count, 0, context);
    return nullptr;
  }
  void wait(JobHandle) override {}
  int calls = 0;
  int throw_at = 0;  // 0: never
  bool keeps_failing = false;  // every enqueue from throw_at on throws (a queue out of memory)
};

StepperOptions every_call_on(ThrowingJobs& jobs, FiniteGuard guard = FiniteGuard::off) {
  StepperOptions o;
  o.jobs = &jobs;
  o.workers = WorkerChoice::all;
  o.inline_below = 0;
  o.guard = guard;
  return o;
}

// Springs between neighbours in index order: a coupled term for the staged path.
Springs neighbour_springs(std::size_t n) {
  Springs s;
  for (std::uint32_t i = 0; i + 1 < n; ++i) s.pairs.push_back({i, i + 1, 0.5, 40, 0.2});
  return s;
}

ForceModel<double> with_callback(ForceModel<double> f) {
  f.add([](const ParticleBlock<double>& b) {
    for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += 0.1 * b.px[i] - 0.2 * b.vz[i];
  });
  return f;
}

ForceModel<double> with_rigid_callback(ForceModel<double> f) {
  f.add([](const RigidBlock<double>& b) {
    for (std::size_t i = 0; i < b.count; ++i) b.tz[i] -= 0.3 * b.qx[i], b.fy[i] += 0.1 * b.wz[i];
  });
  return f;
}

RigidBodySet<double> tumbling(std::size_t n) {
  RigidBodySet<double> set;
  const ParticleSet<double> centers = test::cloud<double>(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double a = double(i % 17) / 17, c = double(i % 5) / 5;
    set.add({centers.position(i), centers.velocity(i), {1, a, c, 0.3}, {a, 1, c}, 1 + a, {1 + a, 2, 2.5 - c}});
  }
  return set;
}

// advance(set, h, steps) with the enqueue that throws at each position in turn: every
// throw leaves the set as `completed` clean steps would, and time() counts them; the rest
// of the steps then give the clean call's bits.
// Under a guard, the steps before the throw were not checked: none is kept. `events`: watched
// on the staged path (the stage state and the events' scan in passes of their own).
template <class Set>
void check_each_enqueue(const char* path, const Set& initial, const ForceModel<double>& forces,
                        const Method& method, FiniteGuard guard = FiniteGuard::off,
                        const EventOptions<double>& events = {}) {
  INFO(path << (guard == FiniteGuard::check ? ", guard check" : guard == FiniteGuard::clamp ? ", guard clamp" : ""));
  constexpr double h = 0.004;
  constexpr std::uint64_t steps = 3;
  ThrowingJobs jobs;
  const auto options = [&] {
    StepperOptions o = every_call_on(jobs, guard);
    o.force_staged = !events.events.empty();
    return o;
  };
  Set clean = initial;
  {
    Stepper<double> s(forces, method, options());
    s.set_events(events);
    s.advance(clean, h, steps);
  }
  const int enqueues = jobs.calls;
  REQUIRE(enqueues > 0);
  for (int k = 1; k <= enqueues; ++k) {
    INFO("enqueue " << k << " of " << enqueues);
    jobs.calls = 0, jobs.throw_at = k;
    Set b = initial;
    Stepper<double> s(forces, method, options());
    s.set_events(events);
    CHECK_THROWS_WITH(s.advance(b, h, steps), "enqueue failed");
    const std::uint64_t completed = s.clock().steps;
    CHECK(completed < steps);
    if (guard != FiniteGuard::off) CHECK(completed == 0);
    Set expected = initial;
    if (completed > 0) Stepper<double>(forces, method, test::serial_options()).advance(expected, h, completed);
    CHECK(test::state_hash(b) == test::state_hash(expected));
    CHECK(s.time() == double(completed) * h);
    jobs.throw_at = 0;
    s.advance(b, h, steps - completed);
    CHECK(test::state_hash(b) == test::state_hash(clean));
  }
}

}  // namespace

// Three blocks (two under the sanitizers, which run every enqueue's case some ten times slower).
#ifdef KINEMA_SANITIZED
constexpr std::size_t kBodies = 1500;
constexpr bool kSanitized = true;
#else
constexpr std::size_t kBodies = 2500;
constexpr bool kSanitized = false;
#endif

TEST_CASE("a throwing enqueue leaves particles as before the step, on every path", "[job_system][throws]") {
  const ParticleSet<double> cloud = test::cloud<double>(kBodies);
  const ForceModel<double> local = test::all_local_terms<double>();
  ForceModel<double> springs = local;
  springs.add(neighbour_springs(cloud.size()));
  ForceModel<double> gravity = local;
  gravity.add(NBody{1e-3, 0.1});
#ifdef KINEMA_SANITIZED
  const auto methods = {&rk4, &velocity_verlet};
#else
  const auto methods = {&rk4, &velocity_verlet, &symplectic_euler, &midpoint};
#endif
  for (const Method* m : methods) {
    INFO(m->name);
    check_each_enqueue("fused", cloud, local, *m);
    check_each_enqueue("block path", cloud, with_callback(local), *m);
    check_each_enqueue("staged, springs", cloud, springs, *m);
    check_each_enqueue("staged, springs and a callback", cloud, with_callback(springs), *m);
    // Under the sanitizers N-body's pairs took most of the test (80 s of rk4's enqueues, 32 s
    // of velocity Verlet's): one method there.
    if (!kSanitized || m == &velocity_verlet) check_each_enqueue("staged, N-body", cloud, gravity, *m);
    check_each_enqueue("staged, springs", cloud, springs, *m, FiniteGuard::check);
    check_each_enqueue("fused", cloud, local, *m, FiniteGuard::check);
    check_each_enqueue("staged, springs", cloud, springs, *m, FiniteGuard::clamp);
    // The events' own pass after the stages' (a throw there once left the step taken).
    const EventOptions<double> plane{{{PlaneEvent{{0, 1, 0}, 0}, Crossing::either}}};
    check_each_enqueue("staged, local terms, an event", cloud, local, *m, FiniteGuard::off, plane);
  }
}

TEST_CASE("a throwing enqueue leaves rigid bodies as before the step, on every path", "[job_system][throws]") {
  const RigidBodySet<double> bodies = tumbling(kBodies);
  ForceModel<double> local = test::rotational_terms<double>();
  for (const Method* m : {&rk4, &velocity_verlet, &bs3}) {
    INFO(m->name);
    check_each_enqueue("rigid", bodies, local, *m);
    check_each_enqueue("rigid block path", bodies, with_rigid_callback(local), *m);
    check_each_enqueue("rigid", bodies, local, *m, FiniteGuard::check);
    check_each_enqueue("rigid block path", bodies, with_rigid_callback(local), *m, FiniteGuard::clamp);
  }
}

TEST_CASE("a throwing enqueue inside advance_to leaves the bodies at an accepted step", "[job_system][throws]") {
  const ParticleSet<double> cloud = test::cloud<double>(kBodies);
  const ForceModel<double> local = test::all_local_terms<double>();
  ForceModel<double> springs = local;
  springs.add(neighbour_springs(cloud.size()));
  const Tolerances tol{1e-8, 1e-8};
  constexpr double t_end = 0.02;
  // Springs save every block in a pass of their own; local terms save each block as it
  // starts (where an enqueue that throws has saved none), with and without an event watched.
  const EventOptions<double> none, floor{{{PlaneEvent{{0, 1, 0}, 0}, Crossing::either}}};
  const std::tuple<const char*, const ForceModel<double>*, const EventOptions<double>*> cases[] = {
      {"springs", &springs, &none}, {"local terms", &local, &none}, {"local terms, an event", &local, &floor}};
  for (const auto& [name, forces, events] : cases) {
    for (const Method* m : {&dopri5, &bs3}) {
      INFO(name << ", " << m->name);
      // The clean run, stopped after every accepted step: the states a throw may leave.
      ThrowingJobs jobs;
      ParticleSet<double> clean = cloud;
      Stepper<double> reference(*forces, *m, every_call_on(jobs));
      reference.set_events(*events);
      std::vector<std::pair<double, std::uint64_t>> accepted{{0.0, test::state_hash(clean)}};
      while (reference.time() < t_end) {
        reference.advance_to(clean, t_end, tol, [] { return true; });
        accepted.emplace_back(reference.time(), test::state_hash(clean));
      }
      const int enqueues = jobs.calls;
      const int samples = kSanitized ? 12 : 40;  // the sanitizers' build runs each a dozen times slower
      for (int k = 1; k <= enqueues; k += std::max(1, enqueues / samples)) {
        for (bool keeps_failing : {false, true}) {
          INFO("enqueue " << k << " of " << enqueues << (keeps_failing ? " and every one after" : ""));
          jobs.calls = 0, jobs.throw_at = k, jobs.keeps_failing = keeps_failing;
          ParticleSet<double> b = cloud;
          Stepper<double> s(*forces, *m, every_call_on(jobs));
          s.set_events(*events);
          try {
            s.advance_to(b, t_end, tol);
          } catch (const std::runtime_error& e) {
            CHECK(std::string(e.what()) == "enqueue failed");
          }
          const std::pair<double, std::uint64_t> left{s.time(), test::state_hash(b)};
          CHECK(std::find(accepted.begin(), accepted.end(), left) != accepted.end());
          jobs.throw_at = 0;  // the same stepper goes on to the end
          s.advance_to(b, t_end, tol);
          CHECK(s.time() == t_end);
          CHECK(all_finite(b));
        }
      }
    }
  }
}

TEST_CASE("a throwing enqueue at a stop event leaves rigid bodies as before the step, the stop undone", "[job_system][throws][events]") {
  // Falling onto a floor with a stop event: a throw anywhere, the settle's enqueues too,
  // leaves the bodies as the steps before it left them, the clock there, and no stop.
  RigidBodySet<double> initial;
  for (std::size_t i = 0; i < kBodies; ++i) {
    initial.add({{double(i % 50), 1 + 1e-4 * double(i), 0}, {}, {1, 0, 0, 0}, {0, 0, 0.1}, 1, {1, 2, 3}});
  }
  ForceModel<double> gravity;
  gravity.add(Gravity{{0, -9.81, 0}});
  const EventOptions<double> stop{{{PlaneEvent{{0, 1, 0}, 0}, Crossing::down, EventAction::stop}}};
  ThrowingJobs jobs;
  Stepper<double> counting(gravity, rk4, every_call_on(jobs));
  counting.set_events(stop);
  RigidBodySet<double> clean = initial;
  counting.advance(clean, 0.05, 20, StopRequest{});
  REQUIRE(counting.stopped_at_event());
  const int enqueues = jobs.calls;
  for (int k = 1; k <= enqueues; ++k) {
    INFO("enqueue " << k << " of " << enqueues);
    jobs.calls = 0, jobs.throw_at = k;
    RigidBodySet<double> b = initial;
    Stepper<double> s(gravity, rk4, every_call_on(jobs));
    s.set_events(stop);
    CHECK_THROWS_WITH(s.advance(b, 0.05, 20, StopRequest{}), "enqueue failed");
    const std::uint64_t completed = s.clock().steps;
    RigidBodySet<double> expected = initial;
    if (completed > 0) Stepper<double>(gravity, rk4, test::serial_options()).advance(expected, 0.05, completed);
    CHECK(test::state_hash(b) == test::state_hash(expected));
    CHECK(s.time() == double(completed) * 0.05);
    CHECK_FALSE(s.stopped_at_event());
  }
}
