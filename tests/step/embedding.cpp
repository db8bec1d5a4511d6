// What an engine that embeds kinema relies on: a throwing callback leaves the set as it
// was, the job-system contract (several host threads, re-entrant calls, a dedicated physics
// thread), and inline_below counting real bodies.
#include <catch2/catch.hpp>

#include <atomic>
#include <cmath>
#include <limits>
#include <numbers>
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
  CHECK(s.time() == 5 + h);
  CHECK(all_finite(b));
}

// A coupled term (every phase a job of its own) that throws in its second call.
class ThrowingTerm final : public CoupledTerm<double> {
 public:
  void accumulate(const ParticleState<double>&, const ParticleBlock<double>& b) const override {
    if (b.begin == 1024 && ++calls_ > 1) throw std::runtime_error("coupled term failed");
  }
  double potential_energy(const ParticleState<double>&) const override { return 0; }

 private:
  mutable std::atomic<int> calls_{0};
};

void check_coupled_throw(const Method& method, StepperOptions o) {
  ParticleSet<double> b = test::cloud<double>(3000);
  ForceModel<double> f = test::all_local_terms<double>();
  f.add(NBody{1e-3, 0.1});
  f.add(std::make_shared<ThrowingTerm>());
  Stepper<double> s(f, method, o);
  const std::uint64_t before = test::state_hash(b);
  CHECK_THROWS_WITH(s.step(b, 0.01), "coupled term failed");
  CHECK(test::state_hash(b) == before);
  CHECK(s.time() == 0);
}

// advance(10) where one block's callback throws in the seventh step: blocks run all their
// steps in turn, yet the set ends as after six steps and the clock says so.
void check_throw_mid_advance(const Method& method, StepperOptions o) {
  const double h = 0.01;
  const double when = 6 * h + (method.kind == MethodKind::runge_kutta ? method.tableau.c[1] * h : h);
  ParticleSet<double> expected = test::cloud<double>(5000);
  Stepper<double>(throwing_model(2048, -1), method, o).advance(expected, h, 6);
  ParticleSet<double> b = test::cloud<double>(5000);
  Stepper<double> s(throwing_model(2048, when), method, o);
  CHECK_THROWS_WITH(s.advance(b, h, 10), "callback failed");
  CHECK(test::state_hash(b) == test::state_hash(expected));
  CHECK(s.time() == Approx(6 * h).epsilon(1e-15));
}

}  // namespace

TEST_CASE("a callback that throws inside advance leaves the set as before the step that threw",
          "[embedding]") {
  TbbJobSystem tbb(2);
  test::ThreadPool pool(2);
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    check_throw_mid_advance(*m, test::serial_options());
    for (JobSystem* jobs : {static_cast<JobSystem*>(&tbb), static_cast<JobSystem*>(&pool)}) {
      StepperOptions o;
      o.jobs = jobs;
      o.workers = WorkerChoice::all;
      check_throw_mid_advance(*m, o);
    }
  }
}

TEST_CASE("a callback that throws leaves the set as before the step, on any job system",
          "[embedding]") {
  TbbJobSystem tbb(2);
  test::ThreadPool pool(2);
  for (const Method* m : {&rk4, &velocity_verlet}) {
    INFO(m->name);
    check_throw_leaves_state(*m, test::serial_options());
    check_coupled_throw(*m, test::serial_options());
    for (JobSystem* jobs : {static_cast<JobSystem*>(&tbb), static_cast<JobSystem*>(&pool)}) {
      StepperOptions o;
      o.jobs = jobs;
      o.workers = WorkerChoice::all;
      check_throw_leaves_state(*m, o);
      check_coupled_throw(*m, o);
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
    o.workers = WorkerChoice::all;
    o.inline_below = 8192;
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
  o.workers = WorkerChoice::all;
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

namespace {

// The bodies of `set` in order, as a set built from scratch.
ParticleSet<double> rebuilt(const ParticleSet<double>& set) {
  ParticleSet<double> out;
  for (std::size_t i = 0; i < set.size(); ++i) {
    if (set.inv_mass()[i] == 0) {
      out.add_kinematic(set.position(i), set.velocity(i));
    } else {
      out.add(set.position(i), set.velocity(i), 1 / set.inv_mass()[i]);
    }
  }
  return out;
}

}  // namespace

TEST_CASE("particles: removal by swap with the last, batch removal, mass and kinematic edits",
          "[embedding][bodies]") {
  ParticleSet<double> b = test::cloud<double>(3000);
  const Vec3<double> last = b.position(2999);
  const double* before = b.px();
  CHECK(b.remove(7) == 2999);
  CHECK(b.size() == 2999);
  CHECK(b.position(7) == last);
  CHECK(b.remove(2998) == ParticleSet<double>::kNoBody);
  CHECK(b.px() == before);  // no reallocation
  // Batch: every move reported, in order, so handles can follow their bodies.
  std::vector<std::size_t> where(b.size());
  for (std::size_t i = 0; i < where.size(); ++i) where[i] = i;  // handle -> index
  std::vector<std::size_t> handle_at = where;                     // index -> handle
  const std::vector<std::size_t> doomed{5, 2000, 17, 2997, 1};
  std::vector<Vec3<double>> kept_position(b.size());
  for (std::size_t i = 0; i < b.size(); ++i) kept_position[i] = b.position(i);
  b.remove(doomed, [&](std::size_t from, std::size_t to) { handle_at[to] = handle_at[from]; });
  REQUIRE(b.size() == 2998 - doomed.size());
  for (std::size_t i = 0; i < b.size(); ++i) {
    const std::size_t h = handle_at[i];
    CHECK(std::find(doomed.begin(), doomed.end(), h) == doomed.end());
    CHECK(b.position(i) == kept_position[h]);
  }
  CHECK_THROWS_WITH(b.remove(std::vector<std::size_t>{3, 3}, [](std::size_t, std::size_t) {}),
                    "body 3: listed twice for removal");
  CHECK_THROWS_WITH(b.remove(b.size()), Catch::StartsWith("body 2993: no such body"));
  // The edited set steps exactly like one built from its bodies: the freed tail is inert.
  b.set_kinematic(3);
  b.set_mass(4, 2.5);
  CHECK_THROWS_WITH(b.set_mass(4, -1), "body 4: mass must be positive and finite, got -1");
  ParticleSet<double> fresh = rebuilt(b);
  const ForceModel<double> f = test::all_local_terms<double>();
  Stepper<double>(f, rk4, test::serial_options()).advance(b, 0.01, 5);
  Stepper<double>(f, rk4, test::serial_options()).advance(fresh, 0.01, 5);
  CHECK(test::state_hash(b) == test::state_hash(fresh));
  CHECK(b.inv_mass()[3] == 0);
}

TEST_CASE("copying a set into one of the same capacity allocates nothing", "[embedding][bodies]") {
  ParticleSet<float> a = test::cloud<float>(5000), snapshot = a;
  const float* memory = snapshot.px();
  Stepper<float>(test::all_local_terms<float>(), rk4, test::serial_options()).step(a, 0.01f);
  snapshot = a;
  CHECK(snapshot.px() == memory);
  CHECK(test::state_hash(snapshot) == test::state_hash(a));
}

namespace {

RigidBodySet<double> boxes(std::size_t n) {
  RigidBodySet<double> set;
  for (std::size_t i = 0; i < n; ++i) {
    const double s = double(i % 7);
    set.add({.position = {s, 1, -s}, .velocity = {0.1 * s, 0, 1}, .orientation = {1, 0.1 * s, 0.2, 0},
             .angular_momentum = {0.3, s, 0.2}, .mass = 1 + s, .inertia = {1, 2 + s, 3}});
  }
  return set;
}

}  // namespace

TEST_CASE("rigid bodies: setters for every field, kinematic bodies, removal, snapshots",
          "[embedding][rigid]") {
  RigidBodySet<double> set = boxes(40);
  set.set_position(3, {5, 6, 7});
  set.set_velocity(3, {1, 0, 0});
  set.set_orientation(3, {0, 0, 2, 0});  // normalized to a half turn about y
  CHECK(set.orientation(3) == Quat<double>{0, 0, 1, 0});
  set.set_angular_momentum(3, {0, 0, 4});
  set.set_inertia(3, {2, 2, 4});
  CHECK(set.angular_velocity(3)[2] == Approx(1));
  set.set_mass(3, 8);
  CHECK_THROWS_WITH(set.set_orientation(3, {0, 0, 0, 0}), "rigid body 3: orientation quaternion is zero");
  CHECK_THROWS_WITH(set.set_inertia(3, {1, 0, 1}), "rigid body 3: inertia moments must be positive");
  set.set_kinematic(5);
  const Quat<double> turned = set.orientation(5);
  const Vec3<double> moving = set.centers().velocity(5);
  CHECK(set.remove(0) == 39);
  RigidBodySet<double> snapshot = boxes(40);  // same capacity
  const double* memory = snapshot.q(0);
  snapshot = set;
  CHECK(snapshot.q(0) == memory);
  // Into a larger set: its arrays are kept, and everything past the copy is inert padding.
  RigidBodySet<double> large = boxes(200);
  large = set;
  REQUIRE(large.size() == set.size());
  for (std::size_t i = large.size(); i < 208; ++i) {
    CHECK(large.q(0)[i] == 1);
    CHECK(large.q(3)[i] == 0);
    CHECK(large.l(1)[i] == 0);
    CHECK(large.inv_inertia(2)[i] == 0);
    CHECK(large.centers().inv_mass()[i] == 0);
  }
  ForceModel<double> f;
  f.add(Gravity{}).add(Torque{{0, 0.5, 0}}).add(AngularDrag{0.1});
  Stepper<double>(f, rk4, test::serial_options()).advance(set, 0.01, 10);
  // The kinematic body kept its velocity and its orientation.
  CHECK(set.orientation(5) == turned);
  CHECK(set.centers().velocity(5) == moving);
  // The snapshot, taken before the steps, steps to the same bits as the edited set.
  Stepper<double>(f, rk4, test::serial_options()).advance(snapshot, 0.01, 10);
  for (std::size_t i = 0; i < set.size(); ++i) {
    INFO("body " << i);
    REQUIRE(snapshot.orientation(i) == set.orientation(i));
    REQUIRE(snapshot.centers().position(i) == set.centers().position(i));
  }
}

TEST_CASE("a fixed timestep runs whole steps, caps a slow frame, and leaves the fraction",
          "[embedding]") {
  FixedTimestep clock(0.01, 4);
  CHECK(clock.steps_for(0.025) == 2);
  CHECK(clock.alpha() == Approx(0.5));
  CHECK(clock.steps_for(0.004) == 0);
  CHECK(clock.alpha() == Approx(0.9));
  CHECK(clock.steps_for(0.001) == 1);  // 0.01 accumulated: exactly one step
  CHECK(clock.alpha() < 1e-9);
  // A 1 s hitch asks for 100 steps: 4 run, 96 are dropped, the fraction stays.
  CHECK(clock.steps_for(1.0032) == 4);
  CHECK(clock.dropped_steps() == 96);
  CHECK(clock.alpha() == Approx(0.32).margin(1e-6));
  CHECK_THROWS_WITH(clock.steps_for(-1), "fixed timestep: a frame's time must be finite and >= 0");
  CHECK_THROWS_AS(FixedTimestep(0), Error);
  CHECK_THROWS_AS(FixedTimestep(1e-320), Error);  // 1 / h is not finite
  // An absurd frame: the cap, a saturated count, and a fraction still in [0, 1).
  CHECK(clock.steps_for(1e300) == 4);
  CHECK(clock.alpha() >= 0);
  CHECK(clock.alpha() < 1);
  // One frame of 1e300 s drops more than 2^64 steps: the count saturates at once.
  FixedTimestep once(1.0 / 60);
  once.steps_for(1e300);
  CHECK(once.dropped_steps() == std::numeric_limits<std::uint64_t>::max());
  // Frames of the largest double: the count saturates, it never wraps back to a small one.
  FixedTimestep hitched(0.01);
  for (int f = 0; f < 3; ++f) hitched.steps_for(std::numeric_limits<double>::max());
  CHECK(hitched.dropped_steps() == std::numeric_limits<std::uint64_t>::max());
  // Over many frames of uneven length the steps add up to the time given, less what was
  // dropped, to within the fraction.
  FixedTimestep steady(1.0 / 60);
  double wall = 0;
  std::uint64_t steps = 0;
  for (int f = 0; f < 10000; ++f) {
    const double frame = 0.004 + 0.001 * (f % 17);
    wall += frame;
    steps += steady.steps_for(frame);
  }
  CHECK(steady.dropped_steps() == 0);
  CHECK(double(steps) / 60 + steady.alpha() / 60 == Approx(wall).epsilon(1e-9));
}

TEST_CASE("the clock's step count never wraps: a call past 2^64 steps is refused before any move",
          "[embedding]") {
  ForceModel<double> gravity;
  gravity.add(Gravity{{0, -1, 0}});
  Stepper<double> stepper(gravity, rk4, on_calling_thread());
  constexpr std::uint64_t most = std::numeric_limits<std::uint64_t>::max();
  stepper.set_clock({0, most - 1, 1.0, 0});
  ParticleSet<double> bodies;
  bodies.add({0, 0, 0}, {1, 0, 0}, 1);
  const ParticleSet<double> before = bodies;
  CHECK_THROWS_WITH(stepper.advance(bodies, 1.0, 3), Catch::Contains("pass 2^64"));
  CHECK(stepper.clock().steps == most - 1);
  CHECK(bodies.px()[0] == before.px()[0]);
  stepper.advance(bodies, 1.0, 1);  // up to the last count is fine
  CHECK(stepper.clock().steps == most);
  // Another step size starts a count of its own; an empty set is counted as well.
  ParticleSet<double> none;
  Stepper<double> empty(gravity, rk4, on_calling_thread());
  empty.advance(none, 0.1, 5);
  CHECK_THROWS_WITH(empty.advance(none, 0.1, most), Catch::Contains("pass 2^64"));
  CHECK(empty.time() == Approx(0.5));
  empty.advance(none, 0.2, most);
  CHECK(empty.clock().steps == most);
}

TEST_CASE("interpolate: positions by lerp, orientations by the short-arc normalized lerp",
          "[embedding][rigid]") {
  for (Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_available(isa)) continue;
    INFO(isa_name(isa));
    ParticleSet<float> a = test::cloud<float>(100), b = a, out;
    for (std::size_t i = 0; i < b.size(); ++i) b.set_position(i, {float(i), 2, -4});
    interpolate(a, b, 0.25f, out, isa);
    REQUIRE(out.size() == 100);
    for (std::size_t i = 0; i < out.size(); ++i) {
      for (int d = 0; d < 3; ++d) {
        CHECK(out.position(i)[d] == std::fma(0.25f, b.position(i)[d] - a.position(i)[d], a.position(i)[d]));
      }
      CHECK(out.velocity(i) == b.velocity(i));
    }
    // Identity to a quarter turn about z: halfway is an eighth turn. The same rotation
    // written as -q must not send the lerp through the long way round.
    RigidBodySet<double> from, to, drawn;
    const double s = std::sqrt(0.5);
    from.add({.orientation = {1, 0, 0, 0}});
    to.add({.position = {2, 0, 0}, .orientation = {-s, 0, 0, -s}});
    interpolate(from, to, 0.5, drawn, isa);
    const Quat<double> q = drawn.orientation(0);
    const double c = std::cos(std::numbers::pi / 8), n = std::sin(std::numbers::pi / 8);
    CHECK(q[0] == Approx(c));
    CHECK(q[3] == Approx(n));
    CHECK(drawn.centers().position(0)[0] == 1);
    // Ends whose difference overflows float: each end at alpha 0 and 1, finite between.
    ParticleSet<float> west, east, far;
    west.add({-3e38f, 0, 0}, {}, 1), east.add({3e38f, 0, 0}, {}, 1);
    for (const float alpha : {0.0f, 0.5f, 1.0f}) {
      interpolate(west, east, alpha, far, isa);
      CHECK(far.position(0)[0] == (alpha == 0 ? -3e38f : alpha == 1 ? 3e38f : 0.0f));
    }
  }
  ParticleSet<float> one = test::cloud<float>(3), two = test::cloud<float>(4), out;
  CHECK_THROWS_WITH(interpolate(one, two, 0.5f, out), "interpolate: the previous set has 3 bodies, the current one 4");
  CHECK_THROWS_WITH(interpolate(one, one, 0.5f, one), "interpolate: out must be a set of its own");
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    CHECK_THROWS_WITH(interpolate(one, one, bad, out), "interpolate: alpha must be finite");
  }
  // A frame clock's alpha (a double) goes straight in for float sets.
  FixedTimestep clock(0.01);
  clock.steps_for(0.005);
  interpolate(one, one, clock.alpha(), out);
  CHECK(out.position(2) == one.position(2));
}

TEST_CASE("forces change between steps: the fused path stays, the bits match a new stepper",
          "[embedding]") {
  ParticleSet<float> a = test::cloud<float>(3000), b = a;
  ForceModel<float> calm = test::all_local_terms<float>(), windy = calm;
  windy.add(Gravity{{4, 0, 0}});
  Stepper<float> one(calm, rk4, test::serial_options());
  one.advance(a, 0.01f, 3);
  one.set_forces(windy);
  CHECK(one.fused());
  one.advance(a, 0.01f, 3);
  Stepper<float> first(calm, rk4, test::serial_options()), second(windy, rk4, test::serial_options());
  first.advance(b, 0.01f, 3);
  second.advance(b, 0.01f, 3);
  CHECK(test::state_hash(a) == test::state_hash(b));
  CHECK(one.time() == Approx(0.06));
  // A bad model is refused and the stepper keeps the one it had.
  ForceModel<float> too_strong;
  too_strong.add(Spring{{0, 0, 0}, 1e39, 0});
  CHECK_THROWS_WITH(one.set_forces(too_strong), Catch::Contains("overflow float"));
  CHECK(one.forces().local_terms().size() == windy.local_terms().size());
}
