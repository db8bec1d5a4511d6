#include "kinema/diagnostics.hpp"

#include <cmath>
#include <type_traits>
#include <utility>
#include <vector>

#include "forces/coupled_forces.hpp"
#include "forces/force_terms.hpp"
#include "forces/rigid_coupling.hpp"

namespace kinema {
namespace {

// Potential energy of a body of mass m at x under the local terms that have one; gravity's
// times the body's gravity factor.
double local_potential(std::span<const LocalTerm> terms, const Vec3<double>& x, double mass, double gravity_factor) {
  double u = 0;
  for (const LocalTerm& term : terms) {
    visit_term(term, [&](const auto& t, auto info) {
      if constexpr (std::is_same_v<std::decay_t<decltype(t)>, Gravity>) {
        u += gravity_factor * info.potential(t, x, mass);
      } else if constexpr (decltype(info)::has_potential) {
        u += info.potential(t, x, mass);
      }
    });
  }
  return u;
}

}  // namespace

template <class T>
double kinetic_energy(const ParticleSet<T>& b) {
  double e = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.inv_mass()[i] == 0) continue;
    const double v2 = double(b.vx()[i]) * b.vx()[i] + double(b.vy()[i]) * b.vy()[i] +
                      double(b.vz()[i]) * b.vz()[i];
    e += 0.5 * v2 / double(b.inv_mass()[i]);
  }
  return e;
}

template <class T>
double potential_energy(const ParticleSet<T>& b, const ForceModel<T>& forces, const StopRequest& stop) {
  double u = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.inv_mass()[i] == 0) continue;
    const Vec3<double> x{double(b.px()[i]), double(b.py()[i]), double(b.pz()[i])};
    u += local_potential(forces.local_terms(), x, 1.0 / double(b.inv_mass()[i]), double(b.gravity_factor(i)));
  }
  const ParticleState<T> all{b.padded_size(), b.px(), b.py(), b.pz(),
                             b.vx(), b.vy(), b.vz(), b.inv_mass()};
  for (const auto& term : forces.coupled_terms()) u += term->potential_energy(all);
  if (forces.nbody()) u += nbody_potential(b, *forces.nbody(), stop);
  return u + spring_potential(b, forces.springs());
}

template <class T>
EnergyReport energy(const ParticleSet<T>& b, const ForceModel<T>& forces, const StopRequest& stop) {
  return {kinetic_energy(b), potential_energy(b, forces, stop)};
}

template <class T>
Vec3<double> momentum(const ParticleSet<T>& b) {
  Vec3<double> p{};
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.inv_mass()[i] == 0) continue;
    const double m = 1.0 / double(b.inv_mass()[i]);
    p[0] += m * b.vx()[i], p[1] += m * b.vy()[i], p[2] += m * b.vz()[i];
  }
  return p;
}

namespace {

// Narrows `first` to an earlier body when `a` has a non-finite entry before it.
template <class T>
void find_non_finite(const T* a, std::size_t count, const char* field,
                     std::optional<NonFinite>& first) {
  const std::size_t end = first ? first->body : count;
  for (std::size_t i = 0; i < end; ++i) {
    if (!std::isfinite(a[i])) {
      first = NonFinite{i, field};
      return;
    }
  }
}

}  // namespace

template <class T>
std::optional<NonFinite> first_non_finite(const ParticleSet<T>& b) {
  std::optional<NonFinite> first;
  const std::pair<const T*, const char*> fields[] = {{b.px(), "px"}, {b.py(), "py"}, {b.pz(), "pz"},
                                                     {b.vx(), "vx"}, {b.vy(), "vy"}, {b.vz(), "vz"}};
  for (const auto& [a, name] : fields) find_non_finite(a, b.size(), name, first);
  return first;
}

template <class T>
bool all_finite(const ParticleSet<T>& b) {
  return !first_non_finite(b);
}

template <class T>
Vec3<double> angular_momentum(const ParticleSet<T>& b) {
  Vec3<double> l{};
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.inv_mass()[i] == 0) continue;
    const double m = 1.0 / double(b.inv_mass()[i]);
    const Vec3<double> x{b.px()[i], b.py()[i], b.pz()[i]}, v{b.vx()[i], b.vy()[i], b.vz()[i]};
    l[0] += m * (x[1] * v[2] - x[2] * v[1]);
    l[1] += m * (x[2] * v[0] - x[0] * v[2]);
    l[2] += m * (x[0] * v[1] - x[1] * v[0]);
  }
  return l;
}

template <class T>
double rotational_energy(const RigidBodySet<T>& b) {
  double e = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const Vec3<double> omega = b.angular_velocity(i);
    const Vec3<T> l = b.angular_momentum(i);
    e += 0.5 * (omega[0] * l[0] + omega[1] * l[1] + omega[2] * l[2]);
  }
  return e;
}

template <class T>
EnergyReport energy(const RigidBodySet<T>& b, const ForceModel<T>& forces) {
  return {kinetic_energy(b.centers()) + rotational_energy(b),
          potential_energy(b.centers(), forces) + rigid_coupling_potential(b, forces)};
}

template <class T>
Vec3<double> angular_momentum(const RigidBodySet<T>& b) {
  Vec3<double> l = angular_momentum(b.centers());
  for (std::size_t i = 0; i < b.size(); ++i) {
    for (int d = 0; d < 3; ++d) l[d] += b.l(d)[i];
  }
  return l;
}

template <class T>
std::optional<NonFinite> first_non_finite(const RigidBodySet<T>& b) {
  std::optional<NonFinite> first = first_non_finite(b.centers());
  const char* names[] = {"qw", "qx", "qy", "qz", "lx", "ly", "lz"};
  for (int k = 0; k < 7; ++k) find_non_finite(k < 4 ? b.q(k) : b.l(k - 4), b.size(), names[k], first);
  return first;
}

template <class T>
bool all_finite(const RigidBodySet<T>& b) {
  return !first_non_finite(b);
}

template <class T>
double spring_frequency_bound(const ParticleSet<T>& b, std::span<const SpringPair> pairs) {
  std::vector<double> stiffness(b.size(), 0.0);  // sum of k at each body
  for (const SpringPair& p : pairs) {
    if (std::max(p.i, p.j) >= b.size()) continue;
    stiffness[p.i] += p.k, stiffness[p.j] += p.k;
  }
  double worst = 0;
  for (std::size_t i = 0; i < b.size(); ++i) worst = std::max(worst, 2 * double(b.inv_mass()[i]) * stiffness[i]);
  return std::sqrt(worst);
}

#define KINEMA_INSTANTIATE(T)                                                  \
  template double spring_frequency_bound(const ParticleSet<T>&, std::span<const SpringPair>); \
  template double kinetic_energy(const ParticleSet<T>&);                       \
  template double potential_energy(const ParticleSet<T>&, const ForceModel<T>&, const StopRequest&); \
  template EnergyReport energy(const ParticleSet<T>&, const ForceModel<T>&, const StopRequest&);   \
  template Vec3<double> momentum(const ParticleSet<T>&);                       \
  template bool all_finite(const ParticleSet<T>&);                             \
  template std::optional<NonFinite> first_non_finite(const ParticleSet<T>&);   \
  template Vec3<double> angular_momentum(const ParticleSet<T>&);               \
  template double rotational_energy(const RigidBodySet<T>&);                   \
  template EnergyReport energy(const RigidBodySet<T>&, const ForceModel<T>&);  \
  template Vec3<double> angular_momentum(const RigidBodySet<T>&);              \
  template bool all_finite(const RigidBodySet<T>&);                            \
  template std::optional<NonFinite> first_non_finite(const RigidBodySet<T>&);
KINEMA_INSTANTIATE(float)
KINEMA_INSTANTIATE(double)
#undef KINEMA_INSTANTIATE

}  // namespace kinema
