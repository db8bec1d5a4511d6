#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "kinema/bodies.hpp"
#include "kinema/error.hpp"

namespace kinema {
namespace {

[[noreturn]] void fail(std::size_t body, const std::string& what) {
  throw Error("rigid body " + std::to_string(body) + ": " + what);
}

template <class T, std::size_t N>
void check_finite(const std::array<T, N>& v, std::size_t body, const char* field) {
  for (T c : v) {
    if (!std::isfinite(c)) fail(body, std::string(field) + " is not finite");
  }
}

// q over its norm, formed in double. Where the sum of squares leaves double's normal range
// (components past 1e154 or under 1e-154, in double sets), the components are first scaled
// by a power of two (exactly); elsewhere the direct form (and its bits).
template <class T>
Quat<T> unit_quaternion(const Quat<T>& q, std::size_t body) {
  std::array<double, 4> c{double(q[0]), double(q[1]), double(q[2]), double(q[3])};
  double squares = 0;
  for (double x : c) squares += x * x;
  if (!(squares >= std::numeric_limits<double>::min() && std::isfinite(squares))) {  // subnormal squares lose digits
    double largest = 0;
    for (double x : c) largest = std::max(largest, std::abs(x));
    if (!(largest > 0)) fail(body, "orientation quaternion is zero");
    const int exponent = std::ilogb(largest);
    squares = 0;
    for (double& x : c) x = std::ldexp(x, -exponent), squares += x * x;
  }
  const double norm = std::sqrt(squares);
  Quat<T> unit;
  for (int k = 0; k < 4; ++k) unit[k] = T(c[k] / norm);
  return unit;
}

template <class T>
Vec3<T> inverse_moments(const Vec3<T>& moments, std::size_t body) {
  check_finite(moments, body, "inertia");
  Vec3<T> inverse;
  for (int d = 0; d < 3; ++d) {
    if (!(moments[d] > 0)) fail(body, "inertia moments must be positive");
    inverse[d] = T(1) / moments[d];
    if (!std::isfinite(inverse[d])) fail(body, "an inertia moment has no finite inverse in this precision");
  }
  return inverse;
}

using Matrix = std::array<std::array<double, 3>, 3>;

// Rotation matrix (columns: the rotated axes) to a unit quaternion (Shepperd's method:
// take the largest of the four squared components to stay well conditioned).
Quat<double> to_quaternion(const Matrix& m) {
  const double trace = m[0][0] + m[1][1] + m[2][2];
  Quat<double> q;
  if (trace >= std::max({m[0][0], m[1][1], m[2][2]})) {
    const double r = std::sqrt(1 + trace), s = 0.5 / r;
    q = {0.5 * r, (m[2][1] - m[1][2]) * s, (m[0][2] - m[2][0]) * s, (m[1][0] - m[0][1]) * s};
  } else if (m[0][0] >= m[1][1] && m[0][0] >= m[2][2]) {
    const double r = std::sqrt(1 + m[0][0] - m[1][1] - m[2][2]), s = 0.5 / r;
    q = {(m[2][1] - m[1][2]) * s, 0.5 * r, (m[0][1] + m[1][0]) * s, (m[0][2] + m[2][0]) * s};
  } else if (m[1][1] >= m[2][2]) {
    const double r = std::sqrt(1 - m[0][0] + m[1][1] - m[2][2]), s = 0.5 / r;
    q = {(m[0][2] - m[2][0]) * s, (m[0][1] + m[1][0]) * s, 0.5 * r, (m[1][2] + m[2][1]) * s};
  } else {
    const double r = std::sqrt(1 - m[0][0] - m[1][1] + m[2][2]), s = 0.5 / r;
    q = {(m[1][0] - m[0][1]) * s, (m[0][2] + m[2][0]) * s, (m[1][2] + m[2][1]) * s, 0.5 * r};
  }
  return q;
}

}  // namespace

Vec3<double> rotate(const Quat<double>& q, const Vec3<double>& v) {
  // v + 2 w (u x v) + 2 u x (u x v), u the vector part.
  const Vec3<double> u{q[1], q[2], q[3]};
  const Vec3<double> t{2 * (u[1] * v[2] - u[2] * v[1]), 2 * (u[2] * v[0] - u[0] * v[2]),
                       2 * (u[0] * v[1] - u[1] * v[0])};
  return {v[0] + q[0] * t[0] + (u[1] * t[2] - u[2] * t[1]),
          v[1] + q[0] * t[1] + (u[2] * t[0] - u[0] * t[2]),
          v[2] + q[0] * t[2] + (u[0] * t[1] - u[1] * t[0])};
}

namespace {

// On the normalized tensor: near 1e308 the difference and the sum would overflow.
void check_symmetric(const Matrix& a) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (std::abs(a[i][j] - a[j][i]) > 1e-9 * (std::abs(a[i][j]) + std::abs(a[j][i]))) {
        throw Error("inertia: the tensor is not symmetric");
      }
    }
  }
}

// Scales `a` by a power of two (exact) so that its largest entry is about 1, and returns
// the exponent: the sums of the Jacobi sweeps cannot overflow near 1e308 nor underflow
// near 1e-308.
int normalize(Matrix& a) {
  double largest = 0;
  for (const auto& row : a) {
    for (double x : row) {
      if (!std::isfinite(x)) throw Error("inertia: not finite");
      largest = std::max(largest, std::abs(x));
    }
  }
  if (largest == 0) throw Error("inertia: the tensor is zero");
  const int exponent = std::ilogb(largest);
  for (auto& row : a) {
    for (double& x : row) x = std::ldexp(x, -exponent);
  }
  return exponent;
}

// Cyclic Jacobi: each rotation zeroes one off-diagonal entry of `a`; a few sweeps converge.
// The rotations accumulate in `v`, whose columns become the eigenvectors.
void diagonalize(Matrix& a, Matrix& v) {
  for (int sweep = 0; sweep < 50; ++sweep) {
    const double off = std::abs(a[0][1]) + std::abs(a[0][2]) + std::abs(a[1][2]);
    if (off <= 1e-15 * (std::abs(a[0][0]) + std::abs(a[1][1]) + std::abs(a[2][2]))) return;
    for (int p = 0; p < 2; ++p) {
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0) continue;
        const double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
        const double t = std::copysign(1.0, theta) / (std::abs(theta) + std::hypot(theta, 1.0));
        const double c = 1 / std::hypot(t, 1.0), s = t * c;
        for (int k = 0; k < 3; ++k) {  // a = J^T a J
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq, a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk, a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {  // v = v J
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq, v[k][q] = s * vkp + c * vkq;
        }
      }
    }
  }
}

}  // namespace

PrincipalFrame principal_frame(const Matrix& inertia) {
  Matrix a = inertia, v{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  const int exponent = normalize(a);
  check_symmetric(a);
  diagonalize(a, v);
  const double det = v[0][0] * (v[1][1] * v[2][2] - v[1][2] * v[2][1]) -
                     v[0][1] * (v[1][0] * v[2][2] - v[1][2] * v[2][0]) +
                     v[0][2] * (v[1][0] * v[2][1] - v[1][1] * v[2][0]);
  if (det < 0) {
    for (int k = 0; k < 3; ++k) v[k][2] = -v[k][2];  // a rotation, not a reflection
  }
  // A moment within round-off of zero (relative to the largest) makes the tensor singular.
  const double top = std::max({a[0][0], a[1][1], a[2][2]});
  Vec3<double> moments;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(a[k][k]) < 64 * std::numeric_limits<double>::epsilon() * top) {
      throw Error("inertia: the tensor is singular (a principal moment is zero to within round-off)");
    }
    if (!(a[k][k] > 0)) throw Error("inertia: the tensor is not positive definite");
    moments[k] = std::ldexp(a[k][k], exponent);
    if (!std::isfinite(moments[k])) throw Error("inertia: a principal moment overflows double");
  }
  return {moments, to_quaternion(v)};
}

template <class T>
void RigidBodySet<T>::grow_rotation_arrays() {
  // Match the centre arrays' capacity; new padding gets the identity orientation.
  const std::size_t target = centers_.capacity(), old = q_[0].size();
  if (target <= old) return;
  torques_.grow(target);  // first: arrays longer than the capacity are harmless, shorter not
  for (auto& a : q_) a.resize(target);
  for (auto& a : l_) a.resize(target);
  for (auto& a : inv_inertia_) a.resize(target);
  for (std::size_t i = old; i < target; ++i) q_[0][i] = 1;
}

template <class T>
void RigidBodySet<T>::reserve(std::size_t count) {
  centers_.reserve(count);
  grow_rotation_arrays();
}

template <class T>
std::size_t RigidBodySet<T>::add(const RigidBodyDesc<T>& b) {
  const std::size_t i = size();
  check_finite(b.orientation, i, "orientation");
  check_finite(b.angular_momentum, i, "angular_momentum");
  const Vec3<T> inverse = inverse_moments(b.inertia, i);
  const Quat<T> unit = unit_quaternion(b.orientation, i);
  try {
    centers_.add(b.position, b.velocity, b.mass);
  } catch (const Error& e) {
    fail(i, std::string(e.what()).substr(std::string(e.what()).find(':') + 2));
  }
  grow_rotation_arrays();
  for (int k = 0; k < 4; ++k) q_[k][i] = unit[k];
  for (int d = 0; d < 3; ++d) {
    l_[d][i] = b.angular_momentum[d];
    inv_inertia_[d][i] = inverse[d];
  }
  return i;
}

template <class T>
void RigidBodySet<T>::pad_rotation_arrays(std::size_t from) {
  for (std::size_t i = from; i < q_[0].size(); ++i) q_[0][i] = 1;
}

template <class T>
RigidBodySet<T>& RigidBodySet<T>::operator=(const RigidBodySet& other) {
  if (this == &other) return *this;
  if (!centers_.copy_fits(other.centers_) || q_[0].size() < other.q_[0].size() ||
      !torques_.fits(other.torques_, centers_.capacity())) {
    return *this = RigidBodySet(other);  // all or nothing
  }
  torques_.assign(other.torques_);  // each fits: no allocation from here on
  centers_ = other.centers_;
  q_ = other.q_, l_ = other.l_, inv_inertia_ = other.inv_inertia_;
  pad_rotation_arrays(other.q_[0].size());  // past the copied arrays: inert padding
  return *this;
}

template <class T>
void RigidBodySet<T>::set_orientation(std::size_t i, const Quat<T>& q) {
  centers_.check_index(i);
  check_finite(q, i, "orientation");
  const Quat<T> unit = unit_quaternion(q, i);
  for (int k = 0; k < 4; ++k) q_[k][i] = unit[k];
}

template <class T>
void RigidBodySet<T>::set_angular_momentum(std::size_t i, const Vec3<T>& l) {
  centers_.check_index(i);
  check_finite(l, i, "angular_momentum");
  for (int d = 0; d < 3; ++d) l_[d][i] = l[d];
}

template <class T>
void RigidBodySet<T>::set_mass(std::size_t i, T mass) {
  centers_.set_mass(i, mass);
}

template <class T>
void RigidBodySet<T>::set_inertia(std::size_t i, const Vec3<T>& moments) {
  centers_.check_index(i);
  const Vec3<T> inverse = inverse_moments(moments, i);
  for (int d = 0; d < 3; ++d) inv_inertia_[d][i] = inverse[d];
}

template <class T>
void RigidBodySet<T>::set_kinematic(std::size_t i) {
  centers_.set_kinematic(i);
  for (int d = 0; d < 3; ++d) inv_inertia_[d][i] = 0;
}

template <class T>
std::size_t RigidBodySet<T>::remove(std::size_t i) {
  centers_.check_index(i);
  const std::size_t last = size() - 1;
  auto move_rotation = [&](std::size_t from, std::size_t to) {
    for (auto& a : q_) a[to] = a[from];
    for (auto& a : l_) a[to] = a[from];
    for (auto& a : inv_inertia_) a[to] = a[from];
    torques_.copy_body(from, to);
  };
  if (i != last) move_rotation(last, i);
  for (auto& a : q_) a[last] = 0;
  for (auto& a : l_) a[last] = 0;
  for (auto& a : inv_inertia_) a[last] = 0;
  torques_.clear_body(last);
  q_[0][last] = 1;  // inert padding: the identity orientation
  return centers_.remove(i);
}

template <class T>
Vec3<T> RigidBodySet<T>::moment_about(std::size_t i, const Vec3<T>& v, const Vec3<T>& world_point,
                                      const char* field) const {
  centers_.check_index(i);
  check_finite(v, i, field);
  check_finite(world_point, i, "point");
  const Vec3<T> x = centers_.position(i);
  const Vec3<double> r{double(world_point[0]) - x[0], double(world_point[1]) - x[1], double(world_point[2]) - x[2]};
  const Vec3<T> moment{T(r[1] * v[2] - r[2] * v[1]), T(r[2] * v[0] - r[0] * v[2]), T(r[0] * v[1] - r[1] * v[0])};
  if (!(std::isfinite(moment[0]) && std::isfinite(moment[1]) && std::isfinite(moment[2]))) {  // no string built else
    check_finite(moment, i, (std::string("moment of the ") + field + " about the centre").c_str());
  }
  return moment;
}

template <class T>
void RigidBodySet<T>::apply_torque(std::size_t i, const Vec3<T>& torque) {
  centers_.check_index(i);
  torques_.add(i, torque, centers_.capacity(), "torque");
}

template <class T>
void RigidBodySet<T>::apply_force_at(std::size_t i, const Vec3<T>& force, const Vec3<T>& world_point) {
  const Vec3<T> moment = moment_about(i, force, world_point, "force");
  centers_.applied_.check_add(i, force, "force");  // both checked before either changes
  torques_.add(i, moment, centers_.capacity(), "torque");
  centers_.apply_force(i, force);
}

template <class T>
void RigidBodySet<T>::apply_angular_impulse(std::size_t i, const Vec3<T>& impulse) {
  centers_.check_index(i);
  check_finite(impulse, i, "angular_impulse");
  if (centers_.inv_mass()[i] == 0) return;  // kinematic
  const Vec3<T> l{l_[0][i] + impulse[0], l_[1][i] + impulse[1], l_[2][i] + impulse[2]};
  check_finite(l, i, "angular momentum after the impulse");
  for (int d = 0; d < 3; ++d) l_[d][i] = l[d];
}

template <class T>
void RigidBodySet<T>::apply_impulse_at(std::size_t i, const Vec3<T>& impulse, const Vec3<T>& world_point) {
  const Vec3<T> moment = moment_about(i, impulse, world_point, "impulse");
  if (centers_.inv_mass()[i] == 0) return;  // kinematic
  const T inv_mass = centers_.inv_mass()[i];
  const Vec3<T> v0 = centers_.velocity(i), l0 = angular_momentum(i);
  const Vec3<T> v{v0[0] + impulse[0] * inv_mass, v0[1] + impulse[1] * inv_mass, v0[2] + impulse[2] * inv_mass};
  const Vec3<T> l{l0[0] + moment[0], l0[1] + moment[1], l0[2] + moment[2]};
  check_finite(v, i, "velocity after the impulse");  // both checked before either changes
  check_finite(l, i, "angular momentum after the impulse");
  for (int d = 0; d < 3; ++d) l_[d][i] = l[d];
  centers_.set_velocity(i, v);
}

template <class T>
Vec3<double> RigidBodySet<T>::angular_velocity(std::size_t i) const {
  Quat<double> q{q_[0][i], q_[1][i], q_[2][i], q_[3][i]};
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (double& c : q) c /= n;
  const Quat<double> conj{q[0], -q[1], -q[2], -q[3]};
  Vec3<double> body = rotate(conj, {double(l_[0][i]), double(l_[1][i]), double(l_[2][i])});
  for (int d = 0; d < 3; ++d) body[d] *= double(inv_inertia_[d][i]);
  return rotate(q, body);
}

template class RigidBodySet<float>;
template class RigidBodySet<double>;

}  // namespace kinema
