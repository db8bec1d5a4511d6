// Checkpoints: k steps, save, restore into new objects, n - k more steps gives the bits of n
// steps straight; damaged or foreign checkpoints are refused with one line and change nothing.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <sys/stat.h>
#include <unistd.h>

#include "support.hpp"

using namespace kinema;

namespace {

template <class T>
RigidBodySet<T> tumbling(std::size_t count) {
  Scene scene;
  scene.generate = GenerateSpec{count, 5, {-3, -3, -3}, {3, 3, 3}, {-1, -1, -1}, {1, 1, 1}, 2, true, {1, 2, 3},
                                {-2, -2, -2}, {2, 2, 2}};
  return make_rigid_bodies<T>(scene);
}

template <class T>
ForceModel<T> chain_and_cluster(std::size_t n) {
  ForceModel<T> f = test::all_local_terms<T>(false, false);
  Springs chain;
  for (std::uint32_t i = 1; i < std::uint32_t(n); ++i) chain.pairs.push_back({i - 1, i, 0.5, 20, 0.1});
  f.add(chain);
  f.add(NBody{0.01, 0.1});
  return f;
}

// The bytes of a checkpoint of one set: every state bit and the clock.
template <class Set, class T>
std::vector<std::byte> bits(const Set& b, const Stepper<T>& s) {
  CheckpointWriter out;
  out.add(b, s);
  return out.bytes();
}

// A run of `calls` calls of `advance` (steps each) straight, against the same run saved after
// `k` calls and restored into a new set and stepper made with `resumed_options`.
template <class Set, class T, class Make, class Call>
void check_resume(Make&& make, const ForceModel<T>& forces, const Method& method, Call&& call, int calls, int k,
                  const StepperOptions& resumed_options) {
  Set straight = make();
  StepperOptions writer = test::serial_options();  // solves as the resumed stepper's
  writer.implicit_preconditioner = resumed_options.implicit_preconditioner;
  Stepper<T> a(forces, method, writer);
  for (int c = 0; c < calls; ++c) call(a, straight, c);

  Set first = make();
  Stepper<T> b(forces, method, writer);
  for (int c = 0; c < k; ++c) call(b, first, c);
  const std::vector<std::byte> saved = bits(first, b);

  Set resumed;  // empty: the checkpoint brings every body
  Stepper<T> r(forces, method, resumed_options);
  CheckpointReader(saved).restore(0, resumed, r);
  CHECK(bits(resumed, r) == saved);
  for (int c = k; c < calls; ++c) call(r, resumed, c);
  CHECK(r.time() == a.time());
  CHECK(bits(resumed, r) == bits(straight, a));
}

StepperOptions two_tbb_threads() {
  static TbbJobSystem tbb(2);
  StepperOptions o;
  o.jobs = &tbb;
  o.workers = WorkerChoice::all;
  return o;
}

std::vector<StepperOptions> resumed_options() {
  std::vector<StepperOptions> all{test::serial_options(Isa::scalar), two_tbb_threads()};
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (isa_available(isa)) all.push_back(test::serial_options(isa));
  }
  return all;
}

// Seven steps of 2 ms per call.
const auto fixed_steps = [](auto& stepper, auto& bodies, int) { stepper.advance(bodies, 2e-3, 7); };

}  // namespace

TEST_CASE("a checkpoint resumes fixed steps bit for bit on every ISA and thread count", "[checkpoint]") {
  for (const StepperOptions& o : resumed_options()) {
    INFO("isa " << isa_name(o.isa) << ", " << (o.jobs ? "2 threads" : "serial"));
    // Particles under local terms (the fused path), float and double.
    check_resume<ParticleSet<float>>([] { return test::cloud<float>(700); }, test::all_local_terms<float>(), rk4,
                                     fixed_steps, 6, 2, o);
    check_resume<ParticleSet<double>>([] { return test::cloud<double>(300); }, test::all_local_terms<double>(),
                                      velocity_verlet, fixed_steps, 5, 3, o);
    // Coupled terms (springs and N-body: the staged path).
    check_resume<ParticleSet<float>>([] { return test::cloud<float>(400); }, chain_and_cluster<float>(400),
                                     velocity_verlet, fixed_steps, 5, 2, o);
    // Rigid bodies under rotational terms.
    check_resume<RigidBodySet<float>>([] { return tumbling<float>(500); }, test::rotational_terms<float>(), rk4,
                                      fixed_steps, 5, 1, o);
    check_resume<RigidBodySet<double>>([] { return tumbling<double>(200); }, test::rotational_terms<double>(), midpoint,
                                       fixed_steps, 4, 3, o);
  }
}

// The shipped cloth's springs and masses on a 10 x 10 grid.
static Scene small_cloth() {
  return parse_scene(R"({"precision": "float", "method": "implicit_euler", "dt": 0.016666666666666666, "steps": 1,
    "forces": [{"type": "gravity", "g": [0, -9.81, 0]},
      {"type": "springs", "grid": {"rows": 10, "columns": 10, "spacing": 0.02, "k": 400, "damping": 0.02,
       "mass": 0.001, "origin": [0, 1, 0], "pinned": "top_corners"}}]})");
}

TEST_CASE("a checkpoint resumes implicit steps bit for bit and refuses other solve options", "[checkpoint][implicit]") {
  const Scene scene = small_cloth();
  const ForceModel<float> forces = make_forces<float>(scene);
  const auto frames = [](auto& stepper, auto& bodies, int) { stepper.advance(bodies, float(1.0 / 60), 2); };
  for (const Method* m : {&implicit_euler, &ros2}) {
    for (StepperOptions o : resumed_options()) {
      for (const ImplicitPreconditioner p : {ImplicitPreconditioner::automatic, ImplicitPreconditioner::multigrid}) {
        o.implicit_preconditioner = p;
        INFO(m->name << ", isa " << isa_name(o.isa) << ", " << (o.jobs ? "2 threads" : "serial") << ", preconditioner " << int(p));
        check_resume<ParticleSet<float>>([&] { return make_particles<float>(scene); }, forces, *m, frames, 4, 1, o);
      }
    }
  }
  ParticleSet<float> bodies = make_particles<float>(scene);
  Stepper<float> defaults(forces, implicit_euler, test::serial_options());
  defaults.advance(bodies, float(1.0 / 60), 1);
  const std::vector<std::byte> saved = bits(bodies, defaults);
  ParticleSet<float> restored;
  StepperOptions tighter = test::serial_options();
  tighter.implicit_tolerance = 1e-5;
  Stepper<float> tighter_stepper(forces, implicit_euler, tighter);
  CHECK_THROWS_WITH(CheckpointReader(saved).restore(0, restored, tighter_stepper),
                    Catch::Contains("implicit solves to 0.001 within 1000 iterations, not this stepper's 1e-05 within 1000"));
  StepperOptions capped = test::serial_options();
  capped.implicit_max_iterations = 50;
  Stepper<float> capped_stepper(forces, implicit_euler, capped);
  CHECK_THROWS_WITH(CheckpointReader(saved).restore(0, restored, capped_stepper), Catch::Contains("not this stepper's 0.001 within 50"));
  StepperOptions spelled_out = test::serial_options();
  spelled_out.implicit_tolerance = 1e-3;  // float's default, named
  Stepper<float> spelled_stepper(forces, implicit_euler, spelled_out);
  CHECK_NOTHROW(CheckpointReader(saved).restore(0, restored, spelled_stepper));
  CHECK(bits(restored, spelled_stepper) == saved);
  // 100 bodies: the default preconditioner is Jacobi's, the same as naming it.
  StepperOptions jacobi = test::serial_options(), multigrid = jacobi;
  jacobi.implicit_preconditioner = ImplicitPreconditioner::jacobi;
  multigrid.implicit_preconditioner = ImplicitPreconditioner::multigrid;
  Stepper<float> jacobi_stepper(forces, implicit_euler, jacobi), multigrid_stepper(forces, implicit_euler, multigrid);
  CHECK_NOTHROW(CheckpointReader(saved).restore(0, restored, jacobi_stepper));
  CHECK_THROWS_WITH(CheckpointReader(saved).restore(0, restored, multigrid_stepper),
                    Catch::Contains("preconditioned by Jacobi, not this stepper's multigrid"));
}

TEST_CASE("a checkpoint resumes error-controlled steps bit for bit", "[checkpoint][adaptive]") {
  // Each call starts from the step the last one proposed, as kinema run makes its calls.
  const auto to = [](Stepper<double>& s, ParticleSet<double>& b, int c) {
    Tolerances tol{1e-6, 1e-6};
    tol.initial_step = s.clock().proposed_step;
    s.advance_to(b, 0.05 * (c + 1), tol);
  };
  for (const bool coupled : {false, true}) {
    INFO((coupled ? "springs and N-body" : "local terms"));
    const ForceModel<double> f = coupled ? chain_and_cluster<double>(300) : test::all_local_terms<double>();
    for (const StepperOptions& o : resumed_options()) {
      check_resume<ParticleSet<double>>([] { return test::cloud<double>(300); }, f, dopri5, to, 6, 3, o);
    }
  }
}

TEST_CASE("an error-controlled call stopped early goes on, in the stepper or from a checkpoint, bit for bit",
          "[checkpoint][adaptive]") {
  // Each call stops after every third accepted step; the controller and the first-same-as-last
  // stage carry over, so the bits are those of one call that never stopped.
  const ForceModel<double> f = chain_and_cluster<double>(300);
  const Tolerances tol{1e-7, 1e-7};
  ParticleSet<double> straight = test::cloud<double>(300);
  Stepper<double> a(f, dopri5, test::serial_options());
  const AdaptiveStats whole = a.advance_to(straight, 0.3, tol);
  REQUIRE(whole.accepted > 20);

  ParticleSet<double> b = test::cloud<double>(300);
  Stepper<double> s(f, dopri5, test::serial_options());
  int accepted = 0;
  const StopRequest every_third = [&] { return ++accepted % 3 == 0; };
  AdaptiveStats total;
  for (int call = 0;; ++call) {
    const std::vector<std::byte> saved = bits(b, s);  // and every other call from a checkpoint
    if (call % 2 == 1) {
      ParticleSet<double> fresh;
      Stepper<double> resumed(f, dopri5, resumed_options()[call / 2 % resumed_options().size()]);
      CheckpointReader(saved).restore(0, fresh, resumed);
      b = std::move(fresh), s = std::move(resumed);
    }
    const AdaptiveStats part = s.advance_to(b, 0.3, tol, every_third);
    total.accepted += part.accepted, total.rejected += part.rejected, total.evaluations += part.evaluations;
    if (!part.stopped) break;
    CHECK(part.accepted == 3);
  }
  CHECK(total.accepted == whole.accepted);
  CHECK(total.rejected == whole.rejected);
  CHECK(total.evaluations == whole.evaluations);
  CHECK(test::state_hash(b) == test::state_hash(straight));
  CHECK(s.time() == a.time());
  // Another end drops what the stopped call kept: the call starts afresh.
  ParticleSet<double> c = test::cloud<double>(300);
  Stepper<double> t(f, dopri5, test::serial_options());
  accepted = 0;
  REQUIRE(t.advance_to(c, 0.3, tol, every_third).stopped);
  const AdaptiveStats other = t.advance_to(c, 0.2999, tol);
  CHECK_FALSE(other.stopped);
  CHECK(t.time() == 0.2999);
}

TEST_CASE("a call stopped early on a clock below zero goes on from a checkpoint bit for bit", "[checkpoint][adaptive]") {
  // The end of a call is a time like the clock, of either sign.
  const ForceModel<double> f = chain_and_cluster<double>(40);
  const Tolerances tol{1e-8, 1e-8};
  ParticleSet<double> straight = test::cloud<double>(40);
  Stepper<double> a(f, dopri5, test::serial_options());
  a.set_time(-10);
  a.advance_to(straight, -9.5, tol);
  ParticleSet<double> b = test::cloud<double>(40);
  Stepper<double> s(f, dopri5, test::serial_options());
  s.set_time(-10);
  int accepted = 0;
  REQUIRE(s.advance_to(b, -9.5, tol, [&] { return ++accepted == 2; }).stopped);
  ParticleSet<double> resumed;
  Stepper<double> r(f, dopri5, test::serial_options());
  CheckpointReader(bits(b, s)).restore(0, resumed, r);
  CHECK_FALSE(r.advance_to(resumed, -9.5, tol).stopped);
  CHECK(test::state_hash(resumed) == test::state_hash(straight));
  CHECK(r.time() == a.time());
  // Checkpoints of both ends are the same bytes: the finished call leaves nothing of its own.
  CHECK(bits(resumed, r) == bits(straight, a));
}

TEST_CASE("a stopped call's set edited before or after a checkpoint starts afresh once restored", "[checkpoint][adaptive]") {
  // Spring to the origin; the call stops after each step. A fresh stepper at the same clock
  // and set, with nothing kept, is what the edited set must get.
  ForceModel<double> f;
  f.add(Spring{{0, 0, 0}, 1, 0});
  const Tolerances tol{1e-6, 1e-6};
  const auto always = [] { return true; };
  const auto stopped = [&](Stepper<double>& s) {
    ParticleSet<double> b;
    b.add({1, 0, 0}, {0, 0, 0}, 1);
    for (int k = 0; k < 3; ++k) REQUIRE(s.advance_to(b, 10, tol, always).stopped);
    return b;
  };
  const auto fresh_step = [&](const ParticleSet<double>& edited, double t) {
    ParticleSet<double> b = edited;
    Stepper<double> fresh(f, dopri5, test::serial_options());
    fresh.set_time(t);
    fresh.advance_to(b, 10, tol, always);
    return test::state_hash(b);
  };
  // Edited, then saved: the record holds no continuation.
  Stepper<double> s(f, dopri5, test::serial_options());
  ParticleSet<double> a = stopped(s);
  a.set_position(0, {-3, 0, 0});
  ParticleSet<double> resumed;
  Stepper<double> r(f, dopri5, test::serial_options());
  CheckpointReader(bits(a, s)).restore(0, resumed, r);
  r.advance_to(resumed, 10, tol, always);
  CHECK(test::state_hash(resumed) == fresh_step(a, s.time()));
  // Saved, restored into a world, then edited there.
  Scene scene;
  scene.particles.push_back(BodySpec{{1, 0, 0}});
  scene.forces.push_back(Spring{{0, 0, 0}, 1, 0});
  World<double> world(scene, dopri5, test::serial_options()), again(scene, dopri5, test::serial_options());
  for (int k = 0; k < 3; ++k) REQUIRE(world.advance_to(10, tol, always).stopped);
  CheckpointWriter out;
  world.save(out);
  again.restore(CheckpointReader(out.bytes()));
  again.particles.set_velocity(0, {0, 2, 0});
  const double t = again.time();
  const ParticleSet<double> edited = again.particles;
  again.advance_to(10, tol, always);
  CHECK(test::state_hash(again.particles) == fresh_step(edited, t));
}

TEST_CASE("a call stopped early keeps its stable-step cap and the forces applied for it", "[checkpoint][adaptive]") {
  // The cap comes from the bodies at the call's start and the forces last to the call's end:
  // a call that goes on must not take either from the bodies as they are when it resumes.
  const ForceModel<double> f = chain_and_cluster<double>(200);
  Tolerances tol{1e-6, 1e-6};
  tol.limit_to_stable_step = true;
  const auto make = [] {
    ParticleSet<double> b = test::cloud<double>(200);
    b.keep_forces(false);
    for (std::size_t i = 0; i < b.size(); i += 5) b.apply_force(i, {0.5, double(i % 3), -1});
    return b;
  };
  ParticleSet<double> straight = make();
  Stepper<double> a(f, dopri5, test::serial_options());
  const AdaptiveStats whole = a.advance_to(straight, 0.2, tol);
  ParticleSet<double> b = make();
  Stepper<double> s(f, dopri5, test::serial_options());
  int accepted = 0;
  std::uint64_t total = 0;
  for (;;) {
    const AdaptiveStats part = s.advance_to(b, 0.2, tol, [&] { return ++accepted % 4 == 0; });
    total += part.accepted;
    if (!part.stopped) break;
    CHECK(b.has_applied_forces());
  }
  CHECK(total == whole.accepted);
  CHECK(test::state_hash(b) == test::state_hash(straight));
  CHECK_FALSE(b.has_applied_forces());  // gone once the call reached its end
}

TEST_CASE("a checkpoint keeps applied forces, the keep flag and kinematic bodies", "[checkpoint]") {
  const auto make = [] {
    ParticleSet<float> b = test::cloud<float>(200);
    b.set_kinematic(17);
    b.keep_forces(true);
    for (std::size_t i = 0; i < b.size(); i += 3) b.apply_force(i, {float(i) * 0.01f, -1, 0.5f});
    return b;
  };
  check_resume<ParticleSet<float>>(make, test::all_local_terms<float>(), rk4, fixed_steps, 4, 2,
                                   test::serial_options());
  const auto make_rigid = [] {
    RigidBodySet<double> b = tumbling<double>(100);
    b.keep_forces(true);
    for (std::size_t i = 0; i < b.size(); i += 4) b.apply_force_at(i, {0, 2, 0}, {1, 0, 0});
    b.set_kinematic(5);
    return b;
  };
  check_resume<RigidBodySet<double>>(make_rigid, test::rotational_terms<double>(), rk4, fixed_steps, 4, 2,
                                     test::serial_options());
  // Forces for the next call only come back as such.
  ParticleSet<float> b = test::cloud<float>(50);
  b.keep_forces(false);  // scenes keep theirs
  b.apply_force(3, {1, 2, 3});
  Stepper<float> s(test::all_local_terms<float>(), rk4, test::serial_options());
  ParticleSet<float> r;
  CheckpointReader(bits(b, s)).restore(0, r, s);
  CHECK(r.applied_force(3) == Vec3<float>{1, 2, 3});
  CHECK_FALSE(r.keeps_forces());
}

namespace {

struct Saved {
  std::vector<std::byte> bytes;
  ParticleSet<float> bodies;
};

Saved small_checkpoint() {
  ParticleSet<float> b = test::cloud<float>(3);
  Stepper<float> s(test::all_local_terms<float>(), rk4, test::serial_options());
  s.advance(b, 0.01f, 3);
  CheckpointWriter out;
  out.add(b, s);
  out.set_user_data({std::byte{1}, std::byte{2}});
  return {out.bytes(), b};
}

template <class V>
void patch(std::vector<std::byte>& data, std::size_t at, V value) {
  std::memcpy(data.data() + at, &value, sizeof(V));
}

// The header's and record 0's own checksums made right again after a patch.
void reseal(std::vector<std::byte>& data) {
  patch(data, 44, crc32c({data.data(), 44}));
  constexpr std::size_t crc_at = kCheckpointRecordBytes - 4;
  patch(data, kCheckpointHeaderBytes + crc_at, crc32c({data.data() + kCheckpointHeaderBytes, crc_at}));
  patch(data, data.size() - 4, crc32c({data.data(), data.size() - 4}));
}

std::string refusal(std::vector<std::byte> data) {
  ParticleSet<float> b = test::cloud<float>(5);
  const ParticleSet<float> before = b;
  Stepper<float> s(test::all_local_terms<float>(), rk4, test::serial_options());
  s.set_time(7);
  try {
    CheckpointReader(std::move(data)).restore(0, b, s);
  } catch (const Error& e) {
    CHECK(test::state_hash(b) == test::state_hash(before));
    CHECK(s.time() == 7);
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("a checkpoint's digest tells clocks and states apart; its trailing checksum cannot", "[checkpoint]") {
  // A body at rest on an anchor at its own position: its state never changes, only the clock.
  ForceModel<double> forces;
  forces.add(Spring{{1, 2, 3}, 5, 0});
  ParticleSet<double> still;
  still.add({1, 2, 3}, {0, 0, 0}, 1);
  Stepper<double> stepper(forces, rk4, test::serial_options());
  const auto write = [&](const std::vector<std::byte>& user = {}) {
    CheckpointWriter w;
    w.add(still, stepper);
    w.set_user_data(user);
    return w;
  };
  const CheckpointWriter start = write();
  stepper.advance(still, 0.01, 10);
  const CheckpointWriter later = write();
  REQUIRE(later.bytes() != start.bytes());  // the clock's fields differ
  // Each header ends with its own CRC-32C, so the running CRC after it is the same constant
  // whatever the header holds: the trailer sees the arrays and user data only.
  CHECK(later.crc() == start.crc());
  CHECK(later.digest() != start.digest());
  CHECK(write().digest() == later.digest());
  CHECK(write({std::byte{1}}).digest() != later.digest());
  still.apply_force(0, {1, 0, 0});  // the arrays
  CHECK(write().digest() != later.digest());
}

TEST_CASE("a damaged checkpoint is refused with one line at every length and every byte", "[checkpoint]") {
  const Saved saved = small_checkpoint();
  REQUIRE(refusal(saved.bytes).empty());
  for (std::size_t n = 0; n < saved.bytes.size(); ++n) {
    const std::string why = refusal({saved.bytes.begin(), saved.bytes.begin() + std::ptrdiff_t(n)});
    INFO("cut to " << n << " bytes");
    CHECK_FALSE(why.empty());
    CHECK(why.find('\n') == std::string::npos);
  }
  for (std::size_t i = 0; i < saved.bytes.size(); ++i) {
    for (const std::byte flip : {std::byte{0x01}, std::byte{0x80}}) {
      std::vector<std::byte> damaged = saved.bytes;
      damaged[i] ^= flip;
      INFO("byte " << i << " flipped");
      CHECK_FALSE(refusal(damaged).empty());
    }
  }
  CHECK_THAT(refusal({}), Catch::Contains("empty"));
}

TEST_CASE("a checkpoint of another version, size, scene, method or precision is refused by name", "[checkpoint]") {
  const Saved saved = small_checkpoint();
  std::vector<std::byte> other_version = saved.bytes;
  patch(other_version, 8, std::uint32_t(2));
  reseal(other_version);
  CHECK_THAT(refusal(other_version), Catch::Contains("version 2") && Catch::Contains("version 1"));

  std::vector<std::byte> too_many = saved.bytes;
  patch(too_many, kCheckpointHeaderBytes + 8, std::uint64_t(1) << 40);  // bodies past the data
  reseal(too_many);
  CHECK_THAT(refusal(too_many), Catch::Contains("more than its"));

  ParticleSet<float> b = saved.bodies;
  Stepper<float> other_model(test::all_local_terms<float>(false), rk4, test::serial_options());
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(0, b, other_model), Catch::Contains("another force model"));
  Stepper<float> other_method(test::all_local_terms<float>(), heun, test::serial_options());
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(0, b, other_method),
                    Catch::Contains("method rk4, not heun"));
  ParticleSet<double> d;
  Stepper<double> in_double(test::all_local_terms<double>(), rk4, test::serial_options());
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(0, d, in_double), Catch::Contains("in float, not double"));
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore_stepper(0, in_double), Catch::Contains("in float, not double"));
  StepperOptions relaxed = test::serial_options();
  relaxed.relaxed_fma = true;
  Stepper<float> relaxed_stepper(test::all_local_terms<float>(), rk4, relaxed);
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(0, b, relaxed_stepper), Catch::Contains("relaxed_fma"));
  RigidBodySet<float> rigid;
  Stepper<float> same(test::all_local_terms<float>(), rk4, test::serial_options());
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(0, rigid, same), Catch::Contains("holds particles"));
  StepperOptions guarded = test::serial_options();
  guarded.guard = FiniteGuard::check;
  Stepper<float> with_guard(test::all_local_terms<float>(), rk4, guarded);
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(0, b, with_guard), Catch::Contains("guard off"));
  CHECK_THROWS_WITH(CheckpointReader(saved.bytes).restore(1, b, same), Catch::Contains("no record 1"));
  // Rigid steps with or without renormalized quaternions differ in their bits: either way
  // round is refused, and the record resumes under the option it was taken with.
  RigidBodySet<double> turning = tumbling<double>(20);
  StepperOptions unnormalized = test::serial_options();
  unnormalized.renormalize_quaternions = false;
  for (const bool renormalized : {true, false}) {
    Stepper<double> taken(test::rotational_terms<double>(), rk4, renormalized ? test::serial_options() : unnormalized);
    taken.advance(turning, 0.01, 3);
    const std::vector<std::byte> record = bits(turning, taken);
    RigidBodySet<double> into;
    Stepper<double> other(test::rotational_terms<double>(), rk4, renormalized ? unnormalized : test::serial_options());
    CHECK_THROWS_WITH(CheckpointReader(record).restore(0, into, other),
                      Catch::Contains(renormalized ? "taken with renormalize_quaternions" : "taken without renormalize_quaternions"));
    Stepper<double> like(test::rotational_terms<double>(), rk4, renormalized ? test::serial_options() : unnormalized);
    CHECK_NOTHROW(CheckpointReader(record).restore(0, into, like));
    // A record from before the option was kept (its byte 0) restores under either.
    std::vector<std::byte> older = record;
    patch(older, kCheckpointHeaderBytes + 116, std::uint8_t(0));
    reseal(older);
    CHECK_NOTHROW(CheckpointReader(older).restore(0, into, other));
  }
}

TEST_CASE("an implicit record without its solve options is refused by name", "[checkpoint][implicit]") {
  const Scene scene = small_cloth();
  const ForceModel<float> forces = make_forces<float>(scene);
  ParticleSet<float> bodies = make_particles<float>(scene);
  Stepper<float> stepper(forces, ros2, test::serial_options());
  stepper.advance(bodies, float(1.0 / 60), 1);
  std::vector<std::byte> old = bits(bodies, stepper);
  patch(old, kCheckpointHeaderBytes + 176, 0.0);  // as records were before they kept them
  patch(old, kCheckpointHeaderBytes + 184, std::int32_t(0));
  reseal(old);
  ParticleSet<float> restored;
  CHECK_THROWS_WITH(CheckpointReader(old).restore(0, restored, stepper),
                    Catch::Contains("before checkpoints kept an implicit method's solve options"));
  CHECK(restored.size() == 0);
}

TEST_CASE("an implicit record keeps its preconditioner: older records read as Jacobi's, others are refused", "[checkpoint][implicit]") {
  // The shipped 64 x 64 cloth: 4096 bodies, multigrid by default.
  const Scene scene = load_scene(std::string(KINEMA_SCENES) + "/cloth.json");
  const ForceModel<float> forces = make_forces<float>(scene);
  StepperOptions jacobi = test::serial_options();
  jacobi.implicit_preconditioner = ImplicitPreconditioner::jacobi;
  const auto taken = [&](const StepperOptions& o) {
    ParticleSet<float> bodies = make_particles<float>(scene);
    Stepper<float> stepper(forces, implicit_euler, o);
    stepper.advance(bodies, float(1.0 / 60), 1);
    return bits(bodies, stepper);
  };
  ParticleSet<float> restored;
  Stepper<float> jacobi_stepper(forces, implicit_euler, jacobi), default_stepper(forces, implicit_euler, test::serial_options());
  CHECK_THROWS_WITH(CheckpointReader(taken(test::serial_options())).restore(0, restored, jacobi_stepper),
                    Catch::Contains("preconditioned by multigrid, not this stepper's Jacobi"));
  // A record from before the byte was kept: its solves were Jacobi's.
  std::vector<std::byte> old = taken(jacobi);
  patch(old, kCheckpointHeaderBytes + 115, std::uint8_t(0));
  reseal(old);
  CHECK_NOTHROW(CheckpointReader(old).restore(0, restored, jacobi_stepper));
  CHECK_THROWS_WITH(CheckpointReader(old).restore(0, restored, default_stepper),
                    Catch::Contains("preconditioned by Jacobi, not this stepper's multigrid"));
  std::vector<std::byte> unknown = taken(jacobi);
  patch(unknown, kCheckpointHeaderBytes + 115, std::uint8_t(7));
  reseal(unknown);
  CHECK_THROWS_WITH(CheckpointReader(unknown).restore(0, restored, jacobi_stepper),
                    Catch::Contains("an unknown preconditioner (7)"));
}

TEST_CASE("a checkpoint made to pass its checksums with a state no set can hold is refused", "[checkpoint]") {
  const Saved saved = small_checkpoint();
  std::vector<std::byte> bad = saved.bytes;
  const std::size_t arrays = kCheckpointHeaderBytes + kCheckpointRecordBytes;
  patch(bad, arrays + 4 * 3 * 2 + 4, std::numeric_limits<float>::quiet_NaN());  // body 1's pz
  reseal(bad);
  CHECK_THAT(refusal(bad), Catch::Contains("body 1") && Catch::Contains("not finite"));
  std::vector<std::byte> negative = saved.bytes;
  patch(negative, arrays + 4 * 3 * 6, -1.0f);  // body 0's inverse mass
  reseal(negative);
  CHECK_THAT(refusal(negative), Catch::Contains("inverse mass"));
}

TEST_CASE("a checkpoint made to pass its checksums with applied forces or a kept stage not finite is refused",
          "[checkpoint][adaptive]") {
  // Three bodies, an applied force on body 1 and a call stopped early that kept dopri5's
  // last stage: the arrays px .. vz, the inverse masses, the applied forces, the kept stage.
  ParticleSet<float> b = test::cloud<float>(3);
  b.apply_force(1, {1.25f, 2, 3});
  b.keep_forces(true);
  const ForceModel<float> f = test::all_local_terms<float>();
  Stepper<float> s(f, dopri5, test::serial_options());
  int accepted = 0;
  REQUIRE(s.advance_to(b, 1.0, {1e-6, 1e-6}, [&] { return ++accepted == 2; }).stopped);
  const std::vector<std::byte> good = bits(b, s);
  const auto array_at = [](int array, int body) {
    return kCheckpointHeaderBytes + kCheckpointRecordBytes + std::size_t(array * 3 + body) * sizeof(float);
  };
  float fx = 0;
  std::memcpy(&fx, good.data() + array_at(7, 1), sizeof fx);
  REQUIRE(fx == 1.25f);  // the layout this test patches
  const auto refused = [&](std::size_t at, float value) {
    std::vector<std::byte> bytes = good;
    patch(bytes, at, value);
    reseal(bytes);
    ParticleSet<float> into = b;
    Stepper<float> r(f, dopri5, test::serial_options());
    try {
      CheckpointReader(std::move(bytes)).restore(0, into, r);
    } catch (const Error& e) {
      CHECK(test::state_hash(into) == test::state_hash(b));
      return std::string(e.what());
    }
    return std::string();
  };
  CHECK_THAT(refused(array_at(7, 1), std::numeric_limits<float>::quiet_NaN()),
             Catch::Contains("body 1's applied force is not finite"));
  CHECK_THAT(refused(array_at(9, 2), std::numeric_limits<float>::infinity()),
             Catch::Contains("body 2's applied force is not finite"));
  CHECK_THAT(refused(array_at(10, 0), std::numeric_limits<float>::quiet_NaN()),
             Catch::Contains("its kept stage is not finite"));
  CHECK_THAT(refused(array_at(12, 2), -std::numeric_limits<float>::infinity()),
             Catch::Contains("its kept stage is not finite"));
}

TEST_CASE("a rigid checkpoint whose orientation cannot be normalized is refused", "[checkpoint][rigid]") {
  // One body turned by the quaternion (0.6, 0.8, 0, 0): its components found in the record's
  // arrays and changed, the checksums made right.
  RigidBodySet<float> b;
  b.add({{0, 0, 0}, {0, 0, 0}, {0.6f, 0.8f, 0, 0}, {0, 0, 0}, 1, {1, 2, 3}});
  Stepper<float> s(ForceModel<float>{}, rk4, test::serial_options());
  CheckpointWriter out;
  out.add(b, s);
  const std::vector<std::byte> good = out.bytes();
  const auto changed = [&](std::initializer_list<std::pair<float, float>> changes) {
    std::vector<std::byte> bytes = good;
    for (const auto& [from, to] : changes) {
      std::size_t at = kCheckpointHeaderBytes + kCheckpointRecordBytes;
      for (float x; at + 4 <= bytes.size(); at += 4) {
        std::memcpy(&x, bytes.data() + at, 4);
        if (std::abs(x - from) < 1e-6f) break;
      }
      REQUIRE(at + 4 <= bytes.size());
      patch(bytes, at, to);
    }
    reseal(bytes);
    return bytes;
  };
  RigidBodySet<float> restored;
  Stepper<float> t(ForceModel<float>{}, rk4, test::serial_options());
  CHECK_THROWS_WITH(CheckpointReader(changed({{0.6f, 0.0f}, {0.8f, 0.0f}})).restore(0, restored, t),
                    Catch::Contains("body 0's orientation quaternion is zero or too small or large to normalize"));
  CHECK_THROWS_AS(CheckpointReader(changed({{0.6f, 3e37f}, {0.8f, 3e37f}})).restore(0, restored, t), Error);
  CHECK(restored.size() == 0);
  CHECK_NOTHROW(CheckpointReader(good).restore(0, restored, t));
  CHECK(restored.q(0)[0] == b.q(0)[0]);
  // Drifted from unit length (renormalize_quaternions = false lets it): kept as it is.
  CHECK_NOTHROW(CheckpointReader(changed({{0.6f, 0.9f}})).restore(0, restored, t));
  CHECK(restored.q(0)[0] == 0.9f);
}

TEST_CASE("checkpoint files: written whole, read only when regular", "[checkpoint][files]") {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("kinema-ckpt-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const Saved saved = small_checkpoint();
  const std::filesystem::path file = dir / "a.ckpt";
  write_whole_file(file, saved.bytes, "checkpoint");
  CHECK(CheckpointReader::load(file).user_data().size() == 2);
  {
    // A write that never commits leaves the earlier file as it was, and no temporary behind.
    WholeFile unfinished(file, "checkpoint");
    unfinished.write(std::string_view("half"));
  }
  CHECK(CheckpointReader::load(file).records() == 1);
  CHECK(std::distance(std::filesystem::directory_iterator(dir), std::filesystem::directory_iterator()) == 1);
  CHECK_THROWS_WITH(CheckpointReader::load(dir), Catch::Contains("is a directory"));
  CHECK_THROWS_WITH(CheckpointReader::load(dir / "missing"), Catch::Contains("No such file"));
  const std::filesystem::path fifo = dir / "fifo";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  CHECK_THROWS_WITH(CheckpointReader::load(fifo), Catch::Contains("not a regular file"));
  CHECK_THROWS_WITH(CheckpointReader::load(file, 16), Catch::Contains("more than the 16 allowed"));
  CHECK_THROWS_WITH(WholeFile(dir, "checkpoint"), Catch::Contains("Is a directory"));
  std::filesystem::remove_all(dir);
}
