#include "forces/rigid_coupling.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <type_traits>
#include <variant>

#include "core/text.hpp"
#include "kinema/error.hpp"

namespace kinema {
namespace {

template <class T>
T narrowed(double value, const std::string& what) {
  const T t = T(value);
  if (!std::isfinite(t)) throw Error(what + ": " + shortest_text(value) + " overflows " + type_name<T>());
  return t;
}

template <class T>
void narrow3(const Vec3<double>& from, T (&to)[3], const std::string& what) {
  for (int d = 0; d < 3; ++d) to[d] = narrowed<T>(from[d], what);
}

template <class R>
struct Vec {
  R c[3];
};

template <class R>
Vec<R> cross(const Vec<R>& a, const Vec<R>& b) {
  return {{a.c[1] * b.c[2] - a.c[2] * b.c[1], a.c[2] * b.c[0] - a.c[0] * b.c[2], a.c[0] * b.c[1] - a.c[1] * b.c[0]}};
}

template <class R>
R dot(const Vec<R>& a, const Vec<R>& b) {
  return a.c[0] * b.c[0] + a.c[1] * b.c[1] + a.c[2] * b.c[2];
}

// R p for the rotation of q / |q| (q as w, x, y, z): p + s (w (u x p) + u x (u x p)),
// s = 2 / |q|^2, the kernels' rotation written on a vector.
template <class R>
Vec<R> rotated(const R q[4], const R p[3]) {
  const R s = R(2) / (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  const Vec<R> u{{q[1], q[2], q[3]}}, v{{p[0], p[1], p[2]}};
  const Vec<R> up = cross(u, v), uup = cross(u, up);
  Vec<R> out;
  for (int d = 0; d < 3; ++d) out.c[d] = v.c[d] + s * (q[0] * up.c[d] + uup.c[d]);
  return out;
}

// A body point at a stage: its arm R p from the centre, world position and velocity.
template <class T>
struct BodyPoint {
  Vec<T> arm, at, velocity;
};

template <class T>
BodyPoint<T> body_point(const RigidStage<T>& s, std::size_t b, const T (&point)[3]) {
  const T q[4] = {s.q[0][b], s.q[1][b], s.q[2][b], s.q[3][b]};
  BodyPoint<T> p;
  p.arm = rotated(q, point);
  const Vec<T> omega{{s.omega[0][b], s.omega[1][b], s.omega[2][b]}};
  const Vec<T> spin = cross(omega, p.arm);
  for (int d = 0; d < 3; ++d) p.at.c[d] = s.x[d][b] + p.arm.c[d], p.velocity.c[d] = s.v[d][b] + spin.c[d];
  return p;
}

template <class T>
void push(const RigidStage<T>& s, std::size_t b, const Vec<T>& arm, const Vec<T>& force) {
  const Vec<T> turn = cross(arm, force);
  for (int d = 0; d < 3; ++d) s.force[d][b] += force.c[d], s.torque[d][b] += turn.c[d];
}

}  // namespace

template <class T>
RigidCoupling<T>::RigidCoupling(const ForceModel<T>& forces) {
  for (const LocalTerm& term : forces.local_terms()) {
    const auto* spring = std::get_if<PointSpring>(&term);
    if (spring == nullptr) continue;
    Point p;
    narrow3(spring->point, p.point, "point_spring.point");
    narrow3(spring->anchor, p.anchor, "point_spring.anchor");
    p.k = narrowed<T>(spring->k, "point_spring.k");
    p.damping = narrowed<T>(spring->damping, "point_spring.damping");
    points_.push_back(p);
  }
  const std::span<const BodySpring> springs = forces.body_springs();
  links_.reserve(springs.size());
  ends_.reserve(2 * springs.size());
  for (std::size_t k = 0; k < springs.size(); ++k) {
    const BodySpring& b = springs[k];
    const std::string name = "body_springs[" + std::to_string(k) + "]";
    Link l{b.i, b.j, {}, {}, narrowed<T>(b.rest, name + ".rest"), narrowed<T>(b.k, name + ".k"),
           narrowed<T>(b.damping, name + ".damping")};
    narrow3(b.point_i, l.point_i, name + ".point_i");
    narrow3(b.point_j, l.point_j, name + ".point_j");
    links_.push_back(l);
    ends_.push_back({b.i, std::uint32_t(k)});
    ends_.push_back({b.j, std::uint32_t(k)});
    covered_ = std::max<std::size_t>(covered_, std::max(b.i, b.j) + std::size_t(1));
  }
  pulls_.resize(links_.size());
  std::sort(ends_.begin(), ends_.end(),
            [](const End& a, const End& b) { return a.body != b.body ? a.body < b.body : a.link < b.link; });
}

void check_body_springs_reach(std::size_t covered, std::size_t bodies) {
  if (covered <= bodies) return;
  throw Error("body_springs: a spring joins body " + std::to_string(covered - 1) + ", but the set has " +
              std::to_string(bodies) + " bodies");
}

template <class T>
void RigidCoupling<T>::check_reach(std::size_t bodies) const {
  check_body_springs_reach(covered_, bodies);
}

// A body spring's force on end i, F_i = -(k (|d| - rest) + damping (V_i - V_j) . u) u, and
// the torques (R point_i) x F_i and (R point_j) x (-F_i); zero for coincident points.
template <class T>
typename RigidCoupling<T>::Pull RigidCoupling<T>::pull(const RigidStage<T>& s, const Link& l) const {
  const BodyPoint<T> a = body_point(s, l.i, l.point_i), b = body_point(s, l.j, l.point_j);
  Vec<T> d, relative;
  for (int c = 0; c < 3; ++c) d.c[c] = a.at.c[c] - b.at.c[c], relative.c[c] = a.velocity.c[c] - b.velocity.c[c];
  Pull p{};
  const T length = std::sqrt(dot(d, d));
  if (length == 0) return p;  // no direction
  const T inverse = T(1) / length;
  Vec<T> u;
  for (int c = 0; c < 3; ++c) u.c[c] = d.c[c] * inverse;
  const T magnitude = l.k * (length - l.rest) + l.damping * dot(relative, u);
  Vec<T> on_i, on_j;
  for (int c = 0; c < 3; ++c) on_i.c[c] = -(magnitude * u.c[c]), on_j.c[c] = -on_i.c[c];
  const Vec<T> turn_i = cross(a.arm, on_i), turn_j = cross(b.arm, on_j);
  for (int c = 0; c < 3; ++c) p.force[c] = on_i.c[c], p.torque_i[c] = turn_i.c[c], p.torque_j[c] = turn_j.c[c];
  return p;
}

template <class T>
void RigidCoupling<T>::evaluate_springs(const RigidStage<T>& s, std::size_t begin, std::size_t end) {
  for (std::size_t k = begin; k < std::min(end, links_.size()); ++k) pulls_[k] = pull(s, links_[k]);
}

template <class T>
void RigidCoupling<T>::add(const RigidStage<T>& s, std::size_t begin, std::size_t end) const {
  for (const Point& p : points_) {
    for (std::size_t b = begin; b < end; ++b) {
      const BodyPoint<T> at = body_point(s, b, p.point);
      Vec<T> force;
      for (int c = 0; c < 3; ++c) force.c[c] = -(p.k * (at.at.c[c] - p.anchor[c])) - p.damping * at.velocity.c[c];
      push(s, b, at.arm, force);
    }
  }
  const auto by_body = [](const End& e, std::size_t body) { return e.body < body; };
  auto e = std::lower_bound(ends_.begin(), ends_.end(), begin, by_body);
  const auto last = std::lower_bound(e, ends_.end(), end, by_body);
  // A body's springs summed apart, then added once.
  while (e != last) {
    const std::uint32_t body = e->body;
    T force[3] = {}, torque[3] = {};
    for (; e != last && e->body == body; ++e) {
      const Pull& p = pulls_[e->link];
      const bool at_i = links_[e->link].i == body;
      for (int c = 0; c < 3; ++c) {
        force[c] += at_i ? p.force[c] : -p.force[c];
        torque[c] += at_i ? p.torque_i[c] : p.torque_j[c];
      }
    }
    for (int c = 0; c < 3; ++c) s.force[c][body] += force[c], s.torque[c][body] += torque[c];
  }
}

namespace {

// A body point's world position, in double.
template <class T>
Vec<double> world_point(const RigidBodySet<T>& set, std::size_t b, const Vec3<double>& point) {
  const Quat<T> qt = set.orientation(b);
  const double q[4] = {qt[0], qt[1], qt[2], qt[3]}, p[3] = {point[0], point[1], point[2]};
  Vec<double> at = rotated(q, p);
  const T* x[3] = {set.centers().px(), set.centers().py(), set.centers().pz()};
  for (int d = 0; d < 3; ++d) at.c[d] += double(x[d][b]);
  return at;
}

}  // namespace

template <class T>
double rigid_coupling_potential(const RigidBodySet<T>& set, const ForceModel<T>& forces) {
  const T* inv_mass = set.centers().inv_mass();
  double u = 0;
  for (const LocalTerm& term : forces.local_terms()) {
    const auto* spring = std::get_if<PointSpring>(&term);
    if (spring == nullptr) continue;
    for (std::size_t b = 0; b < set.size(); ++b) {
      if (inv_mass[b] == 0) continue;
      const Vec<double> at = world_point(set, b, spring->point);
      Vec<double> d;
      for (int c = 0; c < 3; ++c) d.c[c] = at.c[c] - spring->anchor[c];
      u += 0.5 * spring->k * dot(d, d);
    }
  }
  std::size_t covered = 0;
  for (const BodySpring& s : forces.body_springs()) covered = std::max<std::size_t>(covered, std::max(s.i, s.j) + std::size_t(1));
  check_body_springs_reach(covered, set.size());  // as a step refuses a spring past the set
  for (const BodySpring& s : forces.body_springs()) {
    if (inv_mass[s.i] == 0 && inv_mass[s.j] == 0) continue;
    const Vec<double> a = world_point(set, s.i, s.point_i), b = world_point(set, s.j, s.point_j);
    Vec<double> d;
    for (int c = 0; c < 3; ++c) d.c[c] = a.c[c] - b.c[c];
    const double stretch = std::sqrt(dot(d, d)) - s.rest;
    u += 0.5 * s.k * stretch * stretch;
  }
  return u;
}

template class RigidCoupling<float>;
template class RigidCoupling<double>;
template double rigid_coupling_potential(const RigidBodySet<float>&, const ForceModel<float>&);
template double rigid_coupling_potential(const RigidBodySet<double>&, const ForceModel<double>&);

}  // namespace kinema
