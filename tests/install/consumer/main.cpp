// Free fall for one second with rk4: exact for constant acceleration.
#include <cmath>
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
  return std::abs(x[0] - 1) < 1e-12 && std::abs(x[1] + 5) < 1e-12 ? 0 : 1;
}
