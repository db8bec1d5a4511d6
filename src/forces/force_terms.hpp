#pragma once
// Everything kinema knows about each built-in local term, one home per term: its name and
// parameters as scenes spell them (their kinds validate them), which bodies it acts on, how
// it adds into the sums the kernels are given, its potential energy and the reference
// solution that covers it. The validation (forces.cpp), the lowering (force_lowering.cpp),
// the energies (diagnostics.cpp), the scene parser and the reference solutions (through the
// sums and the rules) know the terms only through these homes. A new term: its struct in
// kinema/forces.hpp (and LocalTerm), its TermInfo here, its arithmetic in the kernels.

#include <array>
#include <cmath>
#include <span>
#include <string_view>
#include <tuple>
#include <type_traits>
#include <utility>
#include <variant>

#include "kinema/forces.hpp"

namespace kinema {

// The local terms summed by kind, in double, in the order the model lists them.
struct LocalSums {
  Vec3<double> gravity{};
  double spring_k = 0;
  Vec3<double> weighted_anchor{};  // sum of k a over springs
  double linear = 0;               // linear drag k plus spring damping
  double quadratic = 0;
  int central_count = 0;  // the first kMaxCentralTerms are kept
  std::array<Vec3<double>, kMaxCentralTerms> center{};
  std::array<double, kMaxCentralTerms> mu{};
  Vec3<double> push{};             // sum of point forces: what they do to a rigid body's centre
  Vec3<double> torque{};
  double angular_drag = 0;
  int point_count = 0;  // the first kMaxPointForces are kept
  std::array<Vec3<double>, kMaxPointForces> point{}, point_force{};
};

enum class TermKind {
  local,       // acts on every body's centre (particles and rigid bodies alike)
  rotational,  // acts on rigid bodies only (particles have no orientation)
};

// How reference_states covers a scene holding the term (see accuracy.hpp).
enum class ReferenceRule {
  linear,     // part of y'' + gamma y' + w^2 y = g, solved in closed form
  kepler,     // alone, an elliptic orbit (Kepler's equation)
  no_effect,  // does not move particles
  none,       // no closed form: a numerical reference
};

// A parameter: its key in a scene, whether it must be given, and its member: a vector
// (any finite value) or a number (finite and >= 0).
template <class Term, class Member>
struct Field {
  static constexpr bool is_vector = std::is_same_v<Member, Vec3<double>>;
  const char* key;
  bool required;
  Member Term::*member;
};

template <class Term>
constexpr Field<Term, Vec3<double>> vector_field(const char* key, bool required,
                                                 Vec3<double> Term::*member) {
  return {key, required, member};
}
template <class Term>
constexpr Field<Term, double> number_field(const char* key, bool required, double Term::*member) {
  return {key, required, member};
}

// fn(field) for each field of a term's home, in order.
template <class Info, class Fn>
void for_each_field(Info, Fn&& fn) {
  std::apply([&](const auto&... field) { (fn(field), ...); }, Info::fields);
}

template <class Term>
struct TermInfo;  // one specialization per term, below

// Where a body is, for a term's potential energy (of a body of mass m at x).
using Position = Vec3<double>;

inline double squared_distance(const Position& x, const Vec3<double>& to) {
  double r2 = 0;
  for (int d = 0; d < 3; ++d) r2 += (x[d] - to[d]) * (x[d] - to[d]);
  return r2;
}

template <>
struct TermInfo<Gravity> {
  static constexpr std::string_view name = "gravity";
  static constexpr TermKind kind = TermKind::local;
  static constexpr std::tuple fields{vector_field("g", true, &Gravity::g)};
  static constexpr int max_count = 0;  // no limit
  static constexpr ReferenceRule reference = ReferenceRule::linear;
  static void lower(const Gravity& t, LocalSums& s) {
    for (int d = 0; d < 3; ++d) s.gravity[d] += t.g[d];
  }
  static constexpr bool has_potential = true;
  static double potential(const Gravity& t, const Position& x, double mass) {
    return -(mass * (t.g[0] * x[0] + t.g[1] * x[1] + t.g[2] * x[2]));
  }
};

template <>
struct TermInfo<LinearDrag> {
  static constexpr std::string_view name = "linear_drag";
  static constexpr TermKind kind = TermKind::local;
  static constexpr std::tuple fields{number_field("k", true, &LinearDrag::k)};
  static constexpr int max_count = 0;
  static constexpr ReferenceRule reference = ReferenceRule::linear;
  static void lower(const LinearDrag& t, LocalSums& s) { s.linear += t.k; }
  static constexpr bool has_potential = false;  // dissipative
  static double potential(const LinearDrag&, const Position&, double) { return 0; }
};

template <>
struct TermInfo<QuadraticDrag> {
  static constexpr std::string_view name = "quadratic_drag";
  static constexpr TermKind kind = TermKind::local;
  static constexpr std::tuple fields{number_field("k", true, &QuadraticDrag::k)};
  static constexpr int max_count = 0;
  static constexpr ReferenceRule reference = ReferenceRule::none;
  static void lower(const QuadraticDrag& t, LocalSums& s) { s.quadratic += t.k; }
  static constexpr bool has_potential = false;  // dissipative
  static double potential(const QuadraticDrag&, const Position&, double) { return 0; }
};

template <>
struct TermInfo<Spring> {
  static constexpr std::string_view name = "spring";
  static constexpr TermKind kind = TermKind::local;
  static constexpr std::tuple fields{vector_field("anchor", false, &Spring::anchor),
                                     number_field("k", true, &Spring::k),
                                     number_field("damping", false, &Spring::damping)};
  static constexpr int max_count = 0;
  static constexpr ReferenceRule reference = ReferenceRule::linear;
  // Springs sum to one: -sum k_i (x - a_i) = -K (x - sum k_i a_i / K).
  static void lower(const Spring& t, LocalSums& s) {
    s.spring_k += t.k;
    s.linear += t.damping;
    for (int d = 0; d < 3; ++d) s.weighted_anchor[d] += t.k * t.anchor[d];
  }
  static constexpr bool has_potential = true;  // of the spring; the damping has none
  static double potential(const Spring& t, const Position& x, double) {
    return 0.5 * t.k * squared_distance(x, t.anchor);
  }
};

template <>
struct TermInfo<Central> {
  static constexpr std::string_view name = "central";
  static constexpr TermKind kind = TermKind::local;
  static constexpr std::tuple fields{vector_field("center", false, &Central::center),
                                     number_field("mu", true, &Central::mu)};
  static constexpr int max_count = kMaxCentralTerms;  // evaluated in registers
  static constexpr ReferenceRule reference = ReferenceRule::kepler;
  static void lower(const Central& t, LocalSums& s) {
    if (s.central_count < max_count) s.center[s.central_count] = t.center, s.mu[s.central_count] = t.mu;
    ++s.central_count;  // counts past the limit too: a ForceModel refuses them
  }
  static constexpr bool has_potential = true;
  static double potential(const Central& t, const Position& x, double mass) {
    return -(t.mu * mass / std::sqrt(squared_distance(x, t.center)));
  }
};

template <>
struct TermInfo<Torque> {
  static constexpr std::string_view name = "torque";
  static constexpr TermKind kind = TermKind::rotational;
  static constexpr std::tuple fields{vector_field("torque", true, &Torque::torque)};
  static constexpr int max_count = 0;
  static constexpr ReferenceRule reference = ReferenceRule::no_effect;
  static void lower(const Torque& t, LocalSums& s) {
    for (int d = 0; d < 3; ++d) s.torque[d] += t.torque[d];
  }
  static constexpr bool has_potential = false;  // not of the centres
  static double potential(const Torque&, const Position&, double) { return 0; }
};

template <>
struct TermInfo<AngularDrag> {
  static constexpr std::string_view name = "angular_drag";
  static constexpr TermKind kind = TermKind::rotational;
  static constexpr std::tuple fields{number_field("c", true, &AngularDrag::c)};
  static constexpr int max_count = 0;
  static constexpr ReferenceRule reference = ReferenceRule::no_effect;
  static void lower(const AngularDrag& t, LocalSums& s) { s.angular_drag += t.c; }
  static constexpr bool has_potential = false;  // dissipative
  static double potential(const AngularDrag&, const Position&, double) { return 0; }
};

template <>
struct TermInfo<PointForce> {
  static constexpr std::string_view name = "point_force";
  static constexpr TermKind kind = TermKind::rotational;
  static constexpr std::tuple fields{vector_field("point", true, &PointForce::point),
                                     vector_field("force", true, &PointForce::force)};
  static constexpr int max_count = kMaxPointForces;  // evaluated in registers
  static constexpr ReferenceRule reference = ReferenceRule::no_effect;
  static void lower(const PointForce& t, LocalSums& s) {
    for (int d = 0; d < 3; ++d) s.push[d] += t.force[d];
    if (s.point_count < max_count) s.point[s.point_count] = t.point, s.point_force[s.point_count] = t.force;
    ++s.point_count;  // counts past the limit too: a ForceModel refuses them
  }
  static constexpr bool has_potential = false;  // a body-fixed force is not conservative
  static double potential(const PointForce&, const Position&, double) { return 0; }
};

template <>
struct TermInfo<PointSpring> {
  static constexpr std::string_view name = "point_spring";
  static constexpr TermKind kind = TermKind::rotational;
  static constexpr std::tuple fields{vector_field("point", true, &PointSpring::point),
                                     vector_field("anchor", false, &PointSpring::anchor),
                                     number_field("k", true, &PointSpring::k),
                                     number_field("damping", false, &PointSpring::damping)};
  static constexpr int max_count = 0;
  static constexpr ReferenceRule reference = ReferenceRule::none;  // moves rigid bodies only, no closed form
  static void lower(const PointSpring&, LocalSums&) {}  // the rigid path reads the model's own (rigid_coupling)
  static constexpr bool has_potential = false;  // of the centres alone; rigid_coupling_potential counts it
  static double potential(const PointSpring&, const Position&, double) { return 0; }
};

// fn.template operator()<Term>() for every alternative of LocalTerm, in order.
template <class Fn>
void for_each_term(Fn&& fn) {
  [&]<std::size_t... I>(std::index_sequence<I...>) {
    (fn.template operator()<std::variant_alternative_t<I, LocalTerm>>(), ...);
  }(std::make_index_sequence<std::variant_size_v<LocalTerm>>{});
}

// fn(term, TermInfo<its type>{}) for one term.
template <class Fn>
decltype(auto) visit_term(const LocalTerm& term, Fn&& fn) {
  return std::visit([&](const auto& t) { return fn(t, TermInfo<std::decay_t<decltype(t)>>{}); }, term);
}

// The terms summed by kind, in double, in model order.
inline LocalSums sum_terms(std::span<const LocalTerm> terms) {
  LocalSums sums;
  for (const LocalTerm& term : terms) visit_term(term, [&](const auto& t, auto info) { info.lower(t, sums); });
  return sums;
}

}  // namespace kinema
