// Golden hashes: every shipped scene, stepped a few times with every built-in method, hashes
// to the value stored here, on every instruction set, thread count and path. A change that
// moves one bit of one result fails here. To change results on purpose, run
//   build/release/tests/kinema_tests "[golden]"
// and paste the hashes it prints for the scenes that moved, saying why in the commit.
#include <catch2/catch.hpp>

#include <cinttypes>
#include <map>
#include <string>

#include "support.hpp"

using namespace kinema;

namespace {

void fold(std::uint64_t& hash, const void* data, std::size_t bytes) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) hash = (hash ^ p[i]) * 1099511628211ull;
}

// FNV-1a over every array of both sets, padding included.
template <class T>
void fold(std::uint64_t& hash, const World<T>& world) {
  const auto particles = [&](const ParticleSet<T>& b) {
    for (const T* a : {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz(), b.inv_mass()}) {
      fold(hash, a, b.padded_size() * sizeof(T));
    }
  };
  particles(world.particles);
  const RigidBodySet<T>& r = world.rigid;
  particles(r.centers());
  for (int k = 0; k < 4; ++k) fold(hash, r.q(k), r.padded_size() * sizeof(T));
  for (int d = 0; d < 3; ++d) {
    fold(hash, r.l(d), r.padded_size() * sizeof(T));
    fold(hash, r.inv_inertia(d), r.padded_size() * sizeof(T));
  }
}

// Few steps for the 100k-body scenes, more where a scene has a handful of bodies.
std::uint64_t steps_for(const Scene& scene) {
  const std::size_t bodies = scene.particles.size() + scene.rigid_bodies.size() +
                             (scene.generate ? scene.generate->count : 0);
  return bodies > 1000 ? 3 : 200;
}

template <class T>
std::uint64_t scene_hash(const Scene& scene, StepperOptions options) {
  std::uint64_t hash = 1469598103934665603ull;
  for (const Method* method : builtin_methods) {
    World<T> world(scene, *method, options);
    world.advance(T(scene.dt), steps_for(scene));
    fold(hash, world);
  }
  return hash;
}

std::uint64_t scene_hash(const Scene& scene, Precision precision, StepperOptions options) {
  Scene s = scene;
  s.precision = precision;
  return precision == Precision::single ? scene_hash<float>(s, options) : scene_hash<double>(s, options);
}

// Recorded on the code before the architecture refactor; see the top of the file.
const std::map<std::string, std::uint64_t> kGolden = {
    {"damped_spring/float", 0xd1bfafad6fc3f149ull},
    {"damped_spring/double", 0x84bda509e4c470a7ull},
    {"drag_field/float", 0x0849557808bf5a04ull},
    {"drag_field/double", 0xca6ad3f73c6f979cull},
    {"kepler_circular/float", 0x69f84e463e46380aull},
    {"kepler_circular/double", 0xf0c72634c67847cfull},
    {"kepler_eccentric/float", 0x058913ad620c9d0dull},
    {"kepler_eccentric/double", 0x6156a5cd38b51945ull},
    {"projectiles/float", 0x974be3f502473f96ull},
    {"projectiles/double", 0x9bb8701cf0d2acefull},
    {"spinning_debris/float", 0xc05ed24fd18f226cull},
    {"spinning_debris/double", 0xf340f816e852b6c9ull},
    {"tumbling_book/float", 0xe346c4a965e822f5ull},
    {"tumbling_book/double", 0x47f97bbabdf6086eull},
    // Coupled scenes, recorded when N-body gravity and springs arrived.
    {"binary_orbit/float", 0x0a8050623928860full},
    {"binary_orbit/double", 0x78931eaa731e75ffull},
    {"hanging_chain/float", 0x73f6f2b898ace7deull},
    {"hanging_chain/double", 0x78a89e79f17a0c19ull},
    {"cloth/float", 0xa11cfaa95a727a53ull},
    {"cloth/double", 0x47b3c41f90e622c4ull},
    {"plummer_cluster/float", 0x04aff82ae43f6022ull},
    {"plummer_cluster/double", 0x215c09b5f31b58f0ull},
    // A spring with quadratic drag, recorded when it arrived (the kinked-force charts).
    {"drag_oscillator/double", 0x6f0ba12e7caa84ebull},
    {"drag_oscillator/float", 0x9bead68101df99c4ull},
    // Rigid bodies on point springs and body springs, recorded when they arrived.
    {"heavy_top/float", 0x04dc053ff11a3e8eull},
    {"heavy_top/double", 0xf648651197c72a87ull},
    {"box_chain/float", 0x6179409efb5619e4ull},
    {"box_chain/double", 0xeb9d17e0c63da338ull},
    {"double_pendulum/float", 0x0c4fa1ff14d29703ull},
    {"double_pendulum/double", 0x8e11370a264f2697ull},
    {"stiff_pair/float", 0xbafe74a98a21c463ull},
    {"stiff_pair/double", 0x8e1461eebf63d683ull},
};

}  // namespace

#ifdef KINEMA_SANITIZED  // the reference already takes one thread
constexpr unsigned kThreadCounts[] = {2};
#else
constexpr unsigned kThreadCounts[] = {1, 2, 3};
#endif

TEST_CASE("shipped scenes hash to their stored values on every ISA, thread count and path", "[golden]") {
  const char* names[] = {"damped_spring", "drag_field",      "kepler_circular", "kepler_eccentric",
                         "projectiles",   "spinning_debris", "tumbling_book",   "binary_orbit",
                         "hanging_chain", "cloth",           "plummer_cluster", "drag_oscillator",
                         "heavy_top",     "box_chain",       "double_pendulum", "stiff_pair"};
  for (const char* name : names) {
    Scene scene = load_scene(std::string(KINEMA_SCENES) + "/" + name + ".json");
    // A cluster of 64 bodies: 4096^2 interactions per stage take seconds on the scalar path.
    if (scene.nbody && scene.generate) scene.generate->count = std::min<std::size_t>(scene.generate->count, 64);
    for (const Precision precision : {Precision::single, Precision::dual}) {
      const std::string key = std::string(name) + "/" + std::string(precision_name(precision));
      INFO(key);
      StepperOptions serial = test::serial_options(Isa::scalar);
      const std::uint64_t reference = scene_hash(scene, precision, serial);
      const auto stored = kGolden.find(key);
      if (stored == kGolden.end() || stored->second != reference) {
        std::printf("    {\"%s\", 0x%016" PRIx64 "ull},\n", key.c_str(), reference);
      }
      CHECK(stored != kGolden.end());
      CHECK((stored != kGolden.end() && reference == stored->second));
      for (const Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
        if (!isa_available(isa)) continue;
        for (const unsigned threads : kThreadCounts) {
          StepperOptions o;
          o.isa = isa;
          o.threads = threads;
          o.workers = WorkerChoice::all;
          INFO(isa_name(isa) << ", " << threads << " threads");
          CHECK(scene_hash(scene, precision, o) == reference);
        }
      }
      if (scene.rigid_bodies.empty() && !(scene.generate && scene.generate->rigid)) {
        serial.force_staged = true;
        CHECK(scene_hash(scene, precision, serial) == reference);
      }
    }
  }
}
