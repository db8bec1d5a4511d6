#pragma once
// Energy, momentum and finiteness of a ParticleSet. Sums run serially in double in body
// order, so they are reproducible. Bodies with inv_mass 0 have no defined mass and are left
// out of energies and momentum.

#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"

namespace kinema {

struct EnergyReport {
  double kinetic = 0;
  double potential = 0;  // of the conservative terms: gravity, springs, central, coupled
  double total() const { return kinetic + potential; }
};

template <class T>
double kinetic_energy(const ParticleSet<T>& bodies);
template <class T>
double potential_energy(const ParticleSet<T>& bodies, const ForceModel<T>& forces);
template <class T>
EnergyReport energy(const ParticleSet<T>& bodies, const ForceModel<T>& forces);
template <class T>
Vec3<double> momentum(const ParticleSet<T>& bodies);
// True when every position and velocity is finite.
template <class T>
bool all_finite(const ParticleSet<T>& bodies);

}  // namespace kinema
