// A stop request polled inside the steps of coupled terms (one N-body step takes seconds at
// tens of thousands of bodies): whichever poll it answers at, the set and the clock are at a
// step boundary (an attempt is taken back), and the call can go on to the bits of a call
// that never stopped. The N-body potential polls too.
#include <catch2/catch.hpp>

#include <atomic>
#include <climits>
#include <cmath>
#include <memory>
#include <vector>

#include "parallel/blocks.hpp"
#include "support.hpp"

using namespace kinema;

namespace {

// True from its `fire_at`-th call on; counts every call (workers may poll at once).
StopRequest stop_at(int fire_at, std::shared_ptr<std::atomic<int>> calls = std::make_shared<std::atomic<int>>(0)) {
  return [=] { return ++*calls >= fire_at; };
}

// The polls a call makes when its stop never fires.
template <class Call>
int polls_of(Call&& call) {
  const auto calls = std::make_shared<std::atomic<int>>(0);
  call(stop_at(INT_MAX, calls));
  return calls->load();
}

// Three blocks of bodies: three polls per coupled pass (two blocks under the sanitizers,
// which also stop at fewer polls: every N-body step there takes seconds).
#ifdef KINEMA_SANITIZED
constexpr std::size_t kBodies = 1500;
constexpr int kPollStride = 7;
#else
constexpr std::size_t kBodies = 2500;
constexpr int kPollStride = 3;
#endif

ForceModel<double> gravity_and_local() {
  ForceModel<double> f = test::all_local_terms<double>();
  f.add(NBody{1e-3, 0.1});
  return f;
}

ForceModel<double> springs_and_local(std::size_t n) {
  ForceModel<double> f = test::all_local_terms<double>();
  Springs s;
  for (std::uint32_t i = 0; i + 1 < n; ++i) s.pairs.push_back({i, i + 1, 0.5, 40, 0.2});
  f.add(s);
  return f;
}

// advance(set, h, steps, stop) with the stop firing at every kPollStride-th poll in turn:
// it returns the steps completed, the set and time() those of that many clean steps; the rest
// then give the clean call's bits.
void check_each_poll(const ForceModel<double>& forces, const Method& method, FiniteGuard guard = FiniteGuard::off) {
  INFO(method.name << (guard == FiniteGuard::check ? ", guard check" : ""));
  constexpr double h = 0.004;
  constexpr std::uint64_t steps = 2;
  StepperOptions options = test::serial_options();
  options.guard = guard;
  const ParticleSet<double> initial = test::cloud<double>(kBodies);
  std::vector<std::uint64_t> clean{test::state_hash(initial)};
  ParticleSet<double> b = initial;
  Stepper<double> reference(forces, method, options);
  for (std::uint64_t k = 0; k < steps; ++k) reference.step(b, h), clean.push_back(test::state_hash(b));
  const int polls = polls_of([&](const StopRequest& never) {
    ParticleSet<double> set = initial;
    CHECK(Stepper<double>(forces, method, options).advance(set, h, steps, never) == steps);
    CHECK(test::state_hash(set) == clean.back());
  });
  REQUIRE(polls >= 2 * int(steps) * int(block_count(initial.padded_size())));
  for (int fire_at = 1; fire_at <= polls; fire_at += kPollStride) {
    INFO("poll " << fire_at << " of " << polls);
    ParticleSet<double> set = initial;
    Stepper<double> s(forces, method, options);
    const std::uint64_t taken = s.advance(set, h, steps, stop_at(fire_at));
    REQUIRE(taken < steps);
    // Under the guard a stopped call goes back to where it started.
    if (guard == FiniteGuard::check) CHECK(taken == 0);
    CHECK(test::state_hash(set) == clean[taken]);
    CHECK(s.clock().steps == taken);
    s.advance(set, h, steps - taken);
    CHECK(test::state_hash(set) == clean.back());
  }
}

}  // namespace

TEST_CASE("a stop inside a coupled step leaves the set at a step boundary", "[stop]") {
  const ForceModel<double> gravity = gravity_and_local();
  // velocity_verlet changes the bodies between its coupled passes: its state is kept.
  for (const Method* m : {&rk4, &velocity_verlet}) check_each_poll(gravity, *m);
  check_each_poll(gravity, velocity_verlet, FiniteGuard::check);
  check_each_poll(gravity, rk4, FiniteGuard::check);
}

TEST_CASE("a step of springs is not polled: it costs microseconds a block", "[stop]") {
  // Polling would make kick-drift methods keep the bodies' state every step for nothing.
  const ForceModel<double> springs = springs_and_local(kBodies);
  ParticleSet<double> set = test::cloud<double>(kBodies);
  const int polls = polls_of([&](const StopRequest& never) {
    CHECK(Stepper<double>(springs, velocity_verlet, test::serial_options()).advance(set, 0.004, 2, never) == 2);
  });
  CHECK(polls == 0);
}

TEST_CASE("callbacks' blocks poll the stop before they start: what ran ahead is taken back", "[stop]") {
  // The block path takes all of a call's steps block by block; it once never polled, so a
  // slow game callback could not be stopped.
  ForceModel<double> f = test::all_local_terms<double>();
  f.add([](ParticleBlock<double> b) {
    for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += 0.1 * b.px[i];
  });
  const ParticleSet<double> initial = test::cloud<double>(kBodies);
  constexpr double h = 0.004;
  constexpr std::uint64_t steps = 3;
  ParticleSet<double> clean = initial;
  Stepper<double>(f, rk4, test::serial_options()).advance(clean, h, steps);
  const int polls = polls_of([&](const StopRequest& never) {
    ParticleSet<double> set = initial;
    CHECK(Stepper<double>(f, rk4, test::serial_options()).advance(set, h, steps, never) == steps);
  });
  CHECK(polls == int(block_count(initial.padded_size())));
  for (int fire_at = 1; fire_at <= polls; ++fire_at) {
    INFO("poll " << fire_at << " of " << polls);
    ParticleSet<double> set = initial;
    Stepper<double> s(f, rk4, test::serial_options());
    CHECK(s.advance(set, h, steps, stop_at(fire_at)) == 0);  // the blocks before it ran ahead: put back
    CHECK(test::state_hash(set) == test::state_hash(initial));
    CHECK(s.clock().steps == 0);
    s.advance(set, h, steps);
    CHECK(test::state_hash(set) == test::state_hash(clean));
    // A call of a new step size counts from its own start (its count once wrapped past 2^64).
    CHECK(s.advance(set, 2 * h, steps, stop_at(fire_at)) == 0);
    CHECK(s.time() == Approx(double(steps) * h).epsilon(1e-15));
  }
}

TEST_CASE("a stop inside a coupled step on two threads leaves the set at a step boundary", "[stop][thread]") {
  const ForceModel<double> gravity = gravity_and_local();
  const ParticleSet<double> initial = test::cloud<double>(kBodies);
  constexpr double h = 0.004;
  constexpr std::uint64_t steps = 2;
  StepperOptions two;
  two.threads = 2;
  two.workers = WorkerChoice::all;
  std::vector<std::uint64_t> clean{test::state_hash(initial)};
  ParticleSet<double> b = initial;
  Stepper<double> serial(gravity, velocity_verlet, test::serial_options());
  for (std::uint64_t k = 0; k < steps; ++k) serial.advance(b, h, 1), clean.push_back(test::state_hash(b));
  // Velocity Verlet polls in its two coupled passes a step, once a block (two workers may
  // both poll past the one that fires): the first, the middle and the last step's polls.
  const int per_step = 2 * int(block_count(initial.padded_size()));
  for (int fire_at : {1, per_step, per_step + 2, 2 * per_step}) {
    INFO("poll " << fire_at);
    ParticleSet<double> set = initial;
    Stepper<double> stepper(gravity, velocity_verlet, two);
    const std::uint64_t taken = stepper.advance(set, h, steps, stop_at(fire_at));
    REQUIRE(taken < steps);
    CHECK(taken == (fire_at > per_step ? 1u : 0u));
    CHECK(test::state_hash(set) == clean[taken]);
    CHECK(stepper.clock().steps == taken);
    stepper.advance(set, h, steps - taken);
    CHECK(test::state_hash(set) == clean.back());
  }
}

TEST_CASE("advance_to stopped inside an attempt goes on to the bits of one call", "[stop]") {
  const ForceModel<double> gravity = gravity_and_local();
  const ParticleSet<double> initial = test::cloud<double>(1100);  // two blocks
  Tolerances tol;
  tol.rtol = tol.atol = 1e-6;
  constexpr double t_end = 0.02;
  for (const Method* m : {&dopri5, &bs3}) {
    INFO(m->name);
    ParticleSet<double> whole = initial;
    AdaptiveStats one;
    const int polls = polls_of([&](const StopRequest& never) {
      one = Stepper<double>(gravity, *m, test::serial_options()).advance_to(whole, t_end, tol, {}, never);
    });
    REQUIRE(one.accepted >= 2);
    for (int fire_at = 1; fire_at <= polls; fire_at += std::max(1, polls / (18 / kPollStride))) {
      INFO("poll " << fire_at << " of " << polls);
      ParticleSet<double> set = initial;
      Stepper<double> s(gravity, *m, test::serial_options());
      const AdaptiveStats first = s.advance_to(set, t_end, tol, {}, stop_at(fire_at));
      CHECK(first.stopped);
      const AdaptiveStats rest = s.advance_to(set, t_end, tol);
      CHECK(first.accepted + rest.accepted == one.accepted);
      CHECK(first.rejected + rest.rejected == one.rejected);
      CHECK(s.time() == t_end);
      CHECK(test::state_hash(set) == test::state_hash(whole));
    }
  }
}

TEST_CASE("the stiffness estimate stops inside a force evaluation", "[stop]") {
  const ForceModel<double> gravity = gravity_and_local();
  const ParticleSet<double> bodies = test::cloud<double>(kBodies);
  constexpr int products = 3;
  const int polls = polls_of([&](const StopRequest& never) {
    estimate_stiffness(bodies, gravity, 0, products, test::serial_options(), never);
  });
  // One before each evaluation, and one per block inside it.
  CHECK(polls > 2 * (products + 1));
  const auto calls = std::make_shared<std::atomic<int>>(0);
  CHECK_THROWS_AS(estimate_stiffness(bodies, gravity, 0, products, test::serial_options(), stop_at(2, calls)), Stopped);
  CHECK(calls->load() == 2);
}

TEST_CASE("the N-body potential polls its stop request and keeps its bits", "[stop][energy]") {
  // More than 2^23 pairs: one poll at least.
  ParticleSet<double> bodies = test::cloud<double>(4200);
  bodies.set_kinematic(5);  // no mass: left out
  const NBody term{2e-3, 0.05};
  ForceModel<double> forces;
  forces.add(term);
  // The sum as defined, in body order: the bits the potential must give.
  double expected = 0;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    if (bodies.inv_mass()[i] == 0) continue;
    double row = 0;
    for (std::size_t j = i + 1; j < bodies.size(); ++j) {
      if (bodies.inv_mass()[j] == 0) continue;
      const double dx = bodies.px()[j] - bodies.px()[i], dy = bodies.py()[j] - bodies.py()[i],
                   dz = bodies.pz()[j] - bodies.pz()[i];
      row += (1.0 / bodies.inv_mass()[j]) / std::sqrt(dx * dx + dy * dy + dz * dz + term.softening * term.softening);
    }
    expected -= term.G * (1.0 / bodies.inv_mass()[i]) * row;
  }
  const int polls = polls_of([&](const StopRequest& never) { CHECK(potential_energy(bodies, forces, never) == expected); });
  CHECK(polls >= 1);
  CHECK_THROWS_AS(potential_energy(bodies, forces, stop_at(1)), Stopped);
}
