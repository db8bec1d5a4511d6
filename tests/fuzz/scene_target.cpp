// Fuzz target: any bytes as a scene file, parsed, checked and built (a small one's world too).
// kinema::Error is the expected refusal; anything else escaping (or a sanitizer report) is a
// finding.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "kinema/error.hpp"
#include "kinema/scene.hpp"
#include "kinema/world.hpp"

namespace {

// A small scene's world, coupled terms included (the model's lowering, the steppers, the
// springs' and N-body energies), and the bound on what its run would take. The fuzz build has
// no kernels (no_kernels.cpp): nothing is stepped.
template <class T>
void build_world(const kinema::Scene& scene) {
  (void)kinema::run_bytes<T>(scene);
  if (kinema::evaluation_cost(scene) > 4096 || scene.method == "auto") return;
  try {
    kinema::check_scene<T>(scene);
    const kinema::World<T> world(scene, kinema::method_by_name(scene.method), kinema::on_calling_thread());
    world.main_stepper().check_step_size(T(scene.dt));
    (void)world.total_energy();
  } catch (const kinema::Error&) {
  }
}

template <class T>
void build(const kinema::Scene& scene) {
  try {
    kinema::check_scene<T>(scene);
  } catch (const kinema::Error&) {
  }
  try {
    (void)kinema::make_forces<T>(scene);
  } catch (const kinema::Error&) {
  }
  // Building bodies costs memory in proportion to their number: only small scenes.
  const std::uint64_t listed = scene.particles.size() + scene.rigid_bodies.size();
  if (listed + (scene.generate ? scene.generate->count : 0) > 4096) return;
  try {
    (void)kinema::make_particles<T>(scene);
  } catch (const kinema::Error&) {
  }
  try {
    (void)kinema::make_rigid_bodies<T>(scene);
  } catch (const kinema::Error&) {
  }
  build_world<T>(scene);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  kinema::Scene scene;
  try {
    scene = kinema::parse_scene(text, "fuzz");
  } catch (const kinema::Error&) {
    return 0;
  }
  build<float>(scene);
  build<double>(scene);
  return 0;
}
