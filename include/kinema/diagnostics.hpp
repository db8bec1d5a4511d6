#pragma once
// Energy, momentum and finiteness of a ParticleSet. Sums run serially in double in body
// order, so they are reproducible. Bodies with inv_mass 0 have no defined mass and are left
// out of energies and momentum.

#include <optional>
#include <span>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"
#include "kinema/forces.hpp"

namespace kinema {

struct EnergyReport {
  double kinetic = 0;
  double potential = 0;  // of the conservative terms: gravity, springs, central, coupled
  double total() const { return kinetic + potential; }
};

template <class T>
double kinetic_energy(const ParticleSet<T>& bodies);
// N-body gravity's potential costs N^2 / 2 pairs (seconds at 32768 bodies): `stop` is polled
// every few million of them, and kinema::Stopped thrown once it returns true.
template <class T>
double potential_energy(const ParticleSet<T>& bodies, const ForceModel<T>& forces, const StopRequest& stop = {});
template <class T>
EnergyReport energy(const ParticleSet<T>& bodies, const ForceModel<T>& forces, const StopRequest& stop = {});
template <class T>
Vec3<double> momentum(const ParticleSet<T>& bodies);
// Total angular momentum about the origin: sum of m x cross v.
template <class T>
Vec3<double> angular_momentum(const ParticleSet<T>& bodies);
// True when every position and velocity is finite.
template <class T>
bool all_finite(const ParticleSet<T>& bodies);

// The lowest-numbered body with a non-finite component (NonFinite, kinema/error.hpp);
// nullopt when all are finite.
template <class T>
std::optional<NonFinite> first_non_finite(const ParticleSet<T>& bodies);

// An upper bound on the angular frequency of a spring network's fastest mode (damping
// aside): sqrt(max_i 2 inv_mass_i sum_j k_ij), by Gershgorin's theorem on M^-1 K. Methods
// stable on the imaginary axis hold below h = c / omega: c = 2 for symplectic_euler and
// velocity_verlet, 2 sqrt(2) for rk4. 0 without springs.
template <class T>
double spring_frequency_bound(const ParticleSet<T>& bodies, std::span<const SpringPair> pairs);

// Rigid bodies: kinetic energy includes the rotational part 1/2 L . omega; the potential
// is that of the centres of mass plus the point springs' and body springs'; angular momentum adds each body's spin L to m x cross v.
template <class T>
double rotational_energy(const RigidBodySet<T>& bodies);
template <class T>
EnergyReport energy(const RigidBodySet<T>& bodies, const ForceModel<T>& forces);
template <class T>
Vec3<double> angular_momentum(const RigidBodySet<T>& bodies);
// True when every position, velocity, orientation and angular momentum is finite.
template <class T>
bool all_finite(const RigidBodySet<T>& bodies);
template <class T>
std::optional<NonFinite> first_non_finite(const RigidBodySet<T>& bodies);

}  // namespace kinema
