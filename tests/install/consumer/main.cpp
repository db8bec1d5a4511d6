// Free fall for one second with rk4: exact for constant acceleration.
#include <cmath>
#include <cstddef>
#include <cstdio>

#include <kinema/kinema.hpp>

int main() {
  kinema::ParticleSet<double> bodies;
  bodies.add({0, 0, 0}, {1, 0, 0}, 1);
  kinema::ForceModel<double> forces;
  forces.add(kinema::Gravity{{0, -10, 0}});
  kinema::Stepper<double> stepper(forces, kinema::rk4);
  stepper.advance(bodies, 0.125, 8);
  const auto x = bodies.position(0);
  std::printf("kinema %s: x = (%g, %g, %g)\n", kinema::version, x[0], x[1], x[2]);
  static_assert(KINEMA_VERSION_MAJOR == 0 && KINEMA_VERSION_MINOR >= 1);
  // The same fall with the game giving gravity per body, as the force m g.
  kinema::ParticleSet<double> heavy;
  heavy.add({0, 0, 0}, {1, 0, 0}, 2);
  kinema::ForceModel<double> by_game;
  by_game.add([](kinema::ParticleBlock<double> b) {
    for (std::size_t i = 0; i < b.count; ++i) b.fy[i] += -10 * b.mass[i];
  });
  kinema::Stepper<double>(by_game, kinema::rk4).advance(heavy, 0.125, 8);
  const auto y = heavy.position(0);
  const bool fell = std::abs(x[0] - 1) < 1e-12 && std::abs(x[1] + 5) < 1e-12;
  return fell && std::abs(y[0] - 1) < 1e-12 && std::abs(y[1] + 5) < 1e-12 ? 0 : 1;
}
