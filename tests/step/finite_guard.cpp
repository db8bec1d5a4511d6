// The finiteness guard: off lets a blow-up through, check stops at the step that made it
// with the state before that step kept, clamp holds speeds and keeps the run finite.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <limits>

#include "support.hpp"

using namespace kinema;

namespace {

// Bodies on a stiff anchor spring: the light one (w h = 10) blows up under explicit Euler,
// the heavy ones (w h = 1e-3) stay put. The light one sits in the third block.
constexpr std::size_t kBodies = 3000, kLight = 2500;
constexpr double kH = 0.1;

template <class T>
ParticleSet<T> stiff_cloud() {
  ParticleSet<T> b;
  for (std::size_t i = 0; i < kBodies; ++i) {
    const T s = T(i % 17) / 17;
    b.add({s, 1 - s, T(0.5)}, {0, s, 0}, i == kLight ? T(1) : T(1e8));
  }
  return b;
}

template <class T>
ForceModel<T> stiff_anchor(double k = 1e4) {
  ForceModel<T> f;
  f.add(Spring{{0, 0, 0}, k, 0});
  return f;
}

// The unguarded run one step at a time: the first step whose result is not finite, the
// state before it, and where diagnostics find the first bad value after it.
struct BlowUp {
  std::uint64_t step = 0;
  std::uint64_t hash_before = 0;
  NonFinite where{};
};

template <class T>
BlowUp blow_up_reference() {
  ParticleSet<T> b = stiff_cloud<T>();
  Stepper<T> stepper(stiff_anchor<T>(), euler, test::serial_options());
  for (std::uint64_t k = 1; k <= 2000; ++k) {
    const std::uint64_t before = test::state_hash(b);
    stepper.step(b, T(kH));
    if (const auto bad = first_non_finite(b)) return {k, before, *bad};
  }
  FAIL("the reference run never blew up");
  return {};
}

// Serially, and on two TBB threads with every set split into parallel blocks.
template <class Check>
void on_each_job_system(FiniteGuard guard, Check&& check) {
  TbbJobSystem tbb(2);
  for (bool parallel : {false, true}) {
    for (bool staged : {false, true}) {
      INFO((parallel ? "2 threads" : "serial") << (staged ? ", staged" : ", fused"));
      StepperOptions o = test::serial_options();
      if (parallel) o.jobs = &tbb, o.workers = WorkerChoice::all;
      o.force_staged = staged;
      o.guard = guard;
      check(o);
    }
  }
}

double length(const Vec3<double>& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

template <class T>
Vec3<double> to_double(const Vec3<T>& v) {
  return {double(v[0]), double(v[1]), double(v[2])};
}

}  // namespace

TEMPLATE_TEST_CASE("guard off lets the blow-up through", "[guard]", float, double) {
  using T = TestType;
  ParticleSet<T> b = stiff_cloud<T>();
  Stepper<T> stepper(stiff_anchor<T>(), euler, test::serial_options());
  stepper.advance(b, T(kH), 1000);
  CHECK_FALSE(all_finite(b));
  CHECK(stepper.time() == 1000 * double(T(kH)));
}

TEMPLATE_TEST_CASE("guard check stops at the step that made a value not finite, the state before it kept",
                   "[guard]", float, double) {
  using T = TestType;
  const BlowUp ref = blow_up_reference<T>();
  REQUIRE(ref.where.body == kLight);
  on_each_job_system(FiniteGuard::check, [&](const StepperOptions& o) {
    ParticleSet<T> b = stiff_cloud<T>();
    Stepper<T> stepper(stiff_anchor<T>(), euler, o);
    stepper.advance(b, T(kH), 3);
    try {
      stepper.advance(b, T(kH), 1000);
      FAIL("no NonFiniteError");
    } catch (const NonFiniteError& e) {
      CHECK(e.step == ref.step - 3);
      CHECK(e.body == ref.where.body);
      CHECK(e.field == ref.where.field);
      CHECK(e.time == double(ref.step - 1) * double(T(kH)));
      CHECK_THAT(e.what(), Catch::Contains("body 2500, " + e.field));
    }
    CHECK(test::state_hash(b) == ref.hash_before);
    CHECK(stepper.time() == double(ref.step - 1) * double(T(kH)));
    // The stepper goes on from the kept state.
    stepper.set_forces(stiff_anchor<T>(1));
    stepper.advance(b, T(kH), 10);
    CHECK(all_finite(b));
  });
}

TEMPLATE_TEST_CASE("guard check names a NaN force from a callback at its step", "[guard]", float, double) {
  using T = TestType;
  // From t = 3h on, body 5 gets a NaN force along x: explicit Euler's fourth step turns its
  // vx into NaN (its position moves with the old velocity, still finite).
  ForceModel<T> f = test::all_local_terms<T>();
  f.add([](const ParticleBlock<T>& block) {
    if (block.t < 2.5 * kH) return;
    for (std::size_t i = 0; i < block.count; ++i) {
      if (block.begin + i == 5) block.fx[i] = std::numeric_limits<T>::quiet_NaN();
    }
  });
  ParticleSet<T> expected = test::cloud<T>(100);
  Stepper<T>(f, euler, test::serial_options()).advance(expected, T(kH), 3);
  on_each_job_system(FiniteGuard::check, [&](const StepperOptions& o) {
    ParticleSet<T> b = test::cloud<T>(100);
    Stepper<T> stepper(f, euler, o);
    try {
      stepper.advance(b, T(kH), 10);
      FAIL("no NonFiniteError");
    } catch (const NonFiniteError& e) {
      CHECK(e.step == 4);
      CHECK(e.body == 5);
      CHECK(e.field == "vx");
    }
    CHECK(test::state_hash(b) == test::state_hash(expected));
  });
}

TEMPLATE_TEST_CASE("under a guard, user code that throws leaves the set where the call started, NaN steps unkept",
                   "[guard]", float, double) {
  using T = TestType;
  // Body 5's force is NaN in step 2 and the callback throws in step 3: the steps before the
  // throw were never scanned, so none is kept (kept, the next call would start from NaN).
  ForceModel<T> f = test::all_local_terms<T>();
  f.add([](const ParticleBlock<T>& block) {
    if (block.t > 2.5 * kH) throw std::runtime_error("game code");
    if (block.t < 0.5 * kH) return;
    for (std::size_t i = 0; i < block.count; ++i) {
      if (block.begin + i == 5) block.fx[i] = std::numeric_limits<T>::quiet_NaN();
    }
  });
  for (const FiniteGuard guard : {FiniteGuard::check, FiniteGuard::clamp}) {
    on_each_job_system(guard, [&](const StepperOptions& o) {
      ParticleSet<T> b = test::cloud<T>(100);
      const std::uint64_t before = test::state_hash(b);
      Stepper<T> stepper(f, euler, o);
      CHECK_THROWS_WITH(stepper.advance(b, T(kH), 10), "game code");
      CHECK(test::state_hash(b) == before);
      CHECK(stepper.time() == 0);
      // After steps of another size: the clock as before the call, its origin and size too.
      stepper.set_time(0);
      stepper.advance(b, T(kH / 8), 1);
      const std::uint64_t after_one = test::state_hash(b);
      const StepperClock clock = stepper.clock();
      CHECK_THROWS_WITH(stepper.advance(b, T(kH), 10), "game code");
      CHECK(test::state_hash(b) == after_one);
      CHECK(stepper.time() == double(T(kH / 8)));
      CHECK(stepper.clock().origin == clock.origin);
      CHECK(stepper.clock().steps == clock.steps);
      CHECK(stepper.clock().h == clock.h);
    });
  }
}

TEMPLATE_TEST_CASE("guard check on rigid bodies keeps every array of the last finite state",
                   "[guard][rigid]", float, double) {
  using T = TestType;
  const auto make = [] {
    RigidBodySet<T> b;
    for (std::size_t i = 0; i < 1100; ++i) {  // two blocks
      RigidBodyDesc<T> d;
      d.position = {T(i % 5), 1, 0};
      d.mass = i == 1050 ? T(1) : T(1e8);
      d.angular_momentum = {T(0.3), T(i % 3), T(-1)};
      d.inertia = {1, 2, 3};
      b.add(d);
    }
    return b;
  };
  const auto same_bits = [](const RigidBodySet<T>& a, const RigidBodySet<T>& b) {
    bool same = test::state_hash(a.centers()) == test::state_hash(b.centers());
    for (int k = 0; k < 4; ++k) same &= std::memcmp(a.q(k), b.q(k), a.padded_size() * sizeof(T)) == 0;
    for (int d = 0; d < 3; ++d) same &= std::memcmp(a.l(d), b.l(d), a.padded_size() * sizeof(T)) == 0;
    return same;
  };
  RigidBodySet<T> before = make(), after = make();
  Stepper<T> reference(stiff_anchor<T>(), euler, test::serial_options());
  std::uint64_t step = 0;
  while (all_finite(after) && step < 2000) {
    before = after;
    reference.step(after, T(kH));
    ++step;
  }
  REQUIRE_FALSE(all_finite(after));
  const NonFinite where = *first_non_finite(after);
  on_each_job_system(FiniteGuard::check, [&](StepperOptions o) {
    o.force_staged = false;  // rigid bodies take the fused path only
    RigidBodySet<T> b = make();
    Stepper<T> stepper(stiff_anchor<T>(), euler, o);
    CHECK_THROWS_MATCHES(stepper.advance(b, T(kH), 1000), NonFiniteError,
                         Catch::Predicate<NonFiniteError>([&](const NonFiniteError& e) {
                           return e.step == step && e.body == 1050 && e.body == where.body &&
                                  e.field == where.field;
                         }));
    CHECK(same_bits(b, before));
  });
}

TEMPLATE_TEST_CASE("guard clamp holds speeds to the limit: the blow-up stays finite, slower bodies untouched",
                   "[guard]", float, double) {
  using T = TestType;
  ParticleSet<T> unguarded = stiff_cloud<T>();
  Stepper<T>(stiff_anchor<T>(), euler, test::serial_options()).advance(unguarded, T(kH), 1000);
  on_each_job_system(FiniteGuard::clamp, [&](StepperOptions o) {
    o.max_speed = 10;
    ParticleSet<T> b = stiff_cloud<T>();
    Stepper<T> stepper(stiff_anchor<T>(), euler, o);
    stepper.advance(b, T(kH), 1000);
    REQUIRE(all_finite(b));
    const double ulp = std::numeric_limits<T>::epsilon();
    CHECK(length(to_double(b.velocity(kLight))) <= 10 * (1 + 4 * ulp));
    bool slower_untouched = true;
    for (std::size_t i = 0; i < kBodies; ++i) {
      if (i == kLight) continue;
      slower_untouched &= b.position(i) == unguarded.position(i) && b.velocity(i) == unguarded.velocity(i);
    }
    CHECK(slower_untouched);
  });
}

TEMPLATE_TEST_CASE("guard clamp scales a rigid body's velocity and angular momentum down to the limits",
                   "[guard][rigid]", float, double) {
  using T = TestType;
  StepperOptions o = test::serial_options();
  o.guard = FiniteGuard::clamp;
  o.max_speed = 10;
  o.max_angular_speed = 50;
  RigidBodySet<T> b;
  RigidBodyDesc<T> d;
  d.velocity = {30, 40, 0};
  d.inertia = {1, 2, 4};
  d.angular_momentum = {0, 0, 400};  // omega = 100 about the principal z axis
  b.add(d);
  Stepper<T>(ForceModel<T>{}, velocity_verlet, o).step(b, T(1e-3));
  const double eps = 8 * std::numeric_limits<T>::epsilon();
  CHECK(double(b.centers().velocity(0)[0]) == Approx(6).epsilon(eps));
  CHECK(double(b.centers().velocity(0)[1]) == Approx(8).epsilon(eps));
  CHECK(length(b.angular_velocity(0)) == Approx(50).epsilon(eps));
  CHECK(double(b.angular_momentum(0)[2]) == Approx(200).epsilon(eps));
}

TEST_CASE("guard clamp refuses speed limits that are not positive and finite in T", "[guard][errors]") {
  StepperOptions o = test::serial_options();
  o.guard = FiniteGuard::clamp;
  for (double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(), std::nan("")}) {
    o.max_speed = bad;
    CHECK_THROWS_WITH(Stepper<double>(ForceModel<double>{}, euler, o), Catch::Contains("max_speed"));
  }
  // In float: too large for its square (1e20), or rounding to 0 or below its square's normal
  // range (1e-300, 1e-45, 1e-20), which would have stopped every body.
  for (double bad : {1e39, 1e20, 1e-300, 1e-45, 1e-20}) {
    o.max_speed = bad;
    CHECK_THROWS_WITH(Stepper<float>(ForceModel<float>{}, euler, o),
                      Catch::Contains("max_speed must be > 0 with its square finite and normal in float"));
    if (bad > 1e-150) CHECK_NOTHROW(Stepper<double>(ForceModel<double>{}, euler, o));
  }
  o.max_speed = 1e-18;  // its square 1e-36, normal in float
  CHECK_NOTHROW(Stepper<float>(ForceModel<float>{}, euler, o));
  o.max_speed = 1;
  o.max_angular_speed = 0;
  CHECK_THROWS_WITH(Stepper<double>(ForceModel<double>{}, euler, o), Catch::Contains("max_angular_speed"));
  o.guard = FiniteGuard::off;  // the limits are the clamp's alone
  CHECK_NOTHROW(Stepper<double>(ForceModel<double>{}, euler, o));
}

TEST_CASE("stepper options whose enumerations hold no named value are refused by field", "[guard][errors]") {
  const auto refused = [](auto set, const char* message) {
    StepperOptions o = test::serial_options();
    set(o);
    CHECK_THROWS_WITH(Stepper<double>(ForceModel<double>{}, rk4, o), Catch::Contains(message));
  };
  refused([](StepperOptions& o) { o.guard = FiniteGuard(3); }, "stepper options: guard has no value 3");
  refused([](StepperOptions& o) { o.isa = Isa(-1); }, "stepper options: isa has no value -1");
  refused([](StepperOptions& o) { o.workers = WorkerChoice(2); }, "stepper options: workers has no value 2");
  refused([](StepperOptions& o) { o.implicit_preconditioner = ImplicitPreconditioner(3); },
          "stepper options: implicit_preconditioner has no value 3");
  StepperOptions last = test::serial_options();  // each enumeration's last name is taken
  last.guard = FiniteGuard::clamp, last.workers = WorkerChoice::all;
  last.implicit_preconditioner = ImplicitPreconditioner::multigrid;
  CHECK_NOTHROW(Stepper<double>(ForceModel<double>{}, rk4, last));
}

TEMPLATE_TEST_CASE("scratch_bytes counts the guard's copy and the staged path's stage state", "[guard]",
                   float, double) {
  using T = TestType;
  ParticleSet<T> b = test::cloud<T>(1000);
  const std::size_t array = b.padded_size() * sizeof(T);
  StepperOptions o = test::serial_options();
  Stepper<T> fused(test::all_local_terms<T>(), rk4, o);
  fused.step(b, T(0.01));
  CHECK(fused.scratch_bytes() == 0);
  o.guard = FiniteGuard::check;
  Stepper<T> guarded(test::all_local_terms<T>(), rk4, o);
  guarded.step(b, T(0.01));
  CHECK(guarded.scratch_bytes() == 6 * array);
  o.guard = FiniteGuard::off;
  o.force_staged = true;
  Stepper<T> staged(test::all_local_terms<T>(), rk4, o);
  staged.step(b, T(0.01));
  // Three stages of their own positions and velocities, four of accelerations.
  CHECK(staged.scratch_bytes() >= (3 * 6 + 4 * 3) * array);
}

TEMPLATE_TEST_CASE("guard check on the fused path: the bits of unguarded steps, the set's arrays traded with "
                   "its buffer, padding inert after the set shrinks and grows",
                   "[guard]", float, double) {
  using T = TestType;
  const ForceModel<T> forces = test::all_local_terms<T>();
  StepperOptions o = test::serial_options();
  Stepper<T> plain(forces, rk4, o);
  o.guard = FiniteGuard::check;
  Stepper<T> guarded(forces, rk4, o);
  ParticleSet<T> a = test::cloud<T>(300), b = a;
  const auto step_both = [&](std::uint64_t n) {
    plain.advance(a, T(0.01), n);
    guarded.advance(b, T(0.01), n);
    CHECK(test::state_hash(b) == test::state_hash(a));
  };
  // Every slot past the real bodies holds zero state, whichever buffer the set now has.
  const auto inert_past_size = [&] {
    bool inert = true;
    for (const T* array : {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()}) {
      for (std::size_t i = b.size(); i < b.capacity(); ++i) inert = inert && array[i] == 0;
    }
    return inert;
  };
  const T* before = b.px();
  step_both(1);
  CHECK(b.px() != before);  // the set took the buffer's arrays
  // No step, no trade: the buffer holds the state before the last call.
  const T* now = b.px();
  guarded.advance(b, T(0.01), 0);
  CHECK(b.px() == now);
  CHECK(test::state_hash(b) == test::state_hash(a));
  step_both(3);
  // 100 bodies fewer: their slots in the buffer hold their old state until the guard clears them.
  for (int k = 0; k < 100; ++k) a.remove(a.size() - 1), b.remove(b.size() - 1);
  for (std::uint64_t n : {1, 2}) {
    step_both(n);
    CHECK(inert_past_size());
  }
  for (int k = 0; k < 37; ++k) {
    const Vec3<T> p{T(k), T(1), T(-k)}, v{T(0.5), T(0), T(k) / 8};
    a.add(p, v, T(1.5)), b.add(p, v, T(1.5));
    CHECK(inert_past_size());
  }
  step_both(2);
  CHECK(inert_past_size());
}

TEMPLATE_TEST_CASE("guard check on the fused path: a call that fails leaves no stale state to become padding",
                   "[guard]", float, double) {
  using T = TestType;
  // The light body's spring force overflows in the first step of the first call: the call
  // writes the buffer up to the set's padded size and is taken back, no trade made. Without
  // the light body and the bodies after it, the next calls must leave every slot past the
  // set's size at zero.
  ParticleSet<T> b = stiff_cloud<T>();
  b.set_position(kLight, {std::numeric_limits<T>::max() / 10, 0, 0});
  StepperOptions o = test::serial_options();
  o.guard = FiniteGuard::check;
  Stepper<T> guarded(stiff_anchor<T>(), euler, o);
  CHECK_THROWS_AS(guarded.advance(b, T(kH), 3), NonFiniteError);
  CHECK(guarded.clock().steps == 0);
  while (b.size() > 40) b.remove(b.size() - 1);
  for (int k = 0; k < 2; ++k) {
    guarded.step(b, T(kH));
    bool inert = true;
    for (const T* array : {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()}) {
      for (std::size_t i = b.size(); i < b.capacity(); ++i) inert = inert && array[i] == 0;
    }
    CHECK(inert);
  }
}
