// A scene from JSON text, run as a World for one second of free fall with rk4 (exact).
#include <cmath>
#include <cstdio>

#include <kinema/scenes.hpp>

int main() {
  const kinema::Scene scene = kinema::parse_scene(R"({"precision": "double", "dt": 0.125,
      "particles": [{"position": [0,0,0], "velocity": [1,0,0]}],
      "forces": [{"type": "gravity", "g": [0,-10,0]}]})");
  kinema::World<double> world(scene, kinema::rk4);
  world.advance(0.125, 8);
  const auto x = world.particles.position(0);
  std::printf("x = (%g, %g, %g)\n", x[0], x[1], x[2]);
  return std::abs(x[0] - 1) < 1e-12 && std::abs(x[1] + 5) < 1e-12 ? 0 : 1;
}
