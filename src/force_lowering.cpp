#include "force_lowering.hpp"

#include <cmath>
#include <cstdio>

#include "kinema/error.hpp"

namespace kinema {
namespace {

// A force parameter (or a sum of them) in the stepper's precision. Values valid in double
// can overflow float: refuse them here rather than let inf times a zero inverse mass make
// NaN out of a kinematic body.
template <class T>
T in_precision(double x) {
  const T out = T(x);
  if (!std::isfinite(out)) {
    throw Error("force parameters overflow " + type_name<T>() +
                " (their sum, per kind of term, must be finite in the stepper's precision)");
  }
  return out;
}

template <class T>
kernels::LocalForces<T> lower_local(std::span<const LocalTerm> terms) {
  Vec3<double> g{}, weighted_anchor{}, point_force_sum{};
  double spring_k = 0, linear = 0, quadratic = 0;
  kernels::LocalForces<T> out;
  for (const LocalTerm& term : terms) {
    if (auto* t = std::get_if<Gravity>(&term)) {
      for (int d = 0; d < 3; ++d) g[d] += t->g[d];
    } else if (auto* t = std::get_if<LinearDrag>(&term)) {
      linear += t->k;
    } else if (auto* t = std::get_if<QuadraticDrag>(&term)) {
      quadratic += t->k;
    } else if (auto* t = std::get_if<Spring>(&term)) {
      // Springs sum to one: -sum k_i (x - a_i) = -K (x - sum k_i a_i / K).
      spring_k += t->k;
      linear += t->damping;
      for (int d = 0; d < 3; ++d) weighted_anchor[d] += t->k * t->anchor[d];
    } else if (auto* t = std::get_if<Central>(&term)) {
      const int c = out.central_count++;
      for (int d = 0; d < 3; ++d) out.center[c][d] = in_precision<T>(t->center[d]);
      out.mu[c] = in_precision<T>(t->mu);
    } else if (auto* t = std::get_if<PointForce>(&term)) {
      for (int d = 0; d < 3; ++d) point_force_sum[d] += t->force[d];
    }
  }
  for (int d = 0; d < 3; ++d) {
    out.gravity[d] = in_precision<T>(g[d]);
    out.constant_force[d] = in_precision<T>(point_force_sum[d]);
    out.anchor[d] = spring_k > 0 ? in_precision<T>(weighted_anchor[d] / spring_k) : T(0);
  }
  out.spring_k = in_precision<T>(spring_k);
  out.linear = in_precision<T>(linear);
  out.quadratic = in_precision<T>(quadratic);
  return out;
}

template <class T>
kernels::RotationalForces<T> lower_rotational(std::span<const LocalTerm> terms) {
  Vec3<double> torque{};
  double drag = 0;
  kernels::RotationalForces<T> out;
  for (const LocalTerm& term : terms) {
    if (auto* t = std::get_if<Torque>(&term)) {
      for (int d = 0; d < 3; ++d) torque[d] += t->torque[d];
    } else if (auto* t = std::get_if<AngularDrag>(&term)) {
      drag += t->c;
    } else if (auto* t = std::get_if<PointForce>(&term)) {
      const int p = out.point_count++;
      for (int d = 0; d < 3; ++d) {
        out.point[p][d] = in_precision<T>(t->point[d]);
        out.force[p][d] = in_precision<T>(t->force[d]);
      }
    }
  }
  for (int d = 0; d < 3; ++d) out.torque[d] = in_precision<T>(torque[d]);
  out.angular_drag = in_precision<T>(drag);
  return out;
}

}  // namespace

std::string shortest_text(double x, int digits) {
  char text[32];
  std::snprintf(text, sizeof text, "%.*g", digits, x);
  return text;
}

template <class T>
LoweredForces<T> lower_forces(std::span<const LocalTerm> terms) {
  LoweredForces<T> out;
  out.rigid = lower_local<T>(terms);
  out.particle = out.rigid;
  out.particle.constant_force = {};
  out.rotation = lower_rotational<T>(terms);
  return out;
}

template <class T>
void check_scaled_forces(const kernels::LocalForces<T>& f, T scale, T h) {
  bool finite = std::isfinite(f.spring_k * scale) && std::isfinite(f.linear * scale) &&
                std::isfinite(f.quadratic * scale);
  for (int d = 0; d < 3; ++d) {
    finite = finite && std::isfinite(f.gravity[d] * scale) && std::isfinite(f.constant_force[d] * scale);
  }
  for (int c = 0; c < f.central_count; ++c) finite = finite && std::isfinite(f.mu[c] * scale);
  if (!finite) {
    throw Error("step size h = " + shortest_text(h) + " times the force parameters overflows " +
                type_name<T>() + "; take a smaller step");
  }
}

template LoweredForces<float> lower_forces<float>(std::span<const LocalTerm>);
template LoweredForces<double> lower_forces<double>(std::span<const LocalTerm>);
template void check_scaled_forces<float>(const kernels::LocalForces<float>&, float, float);
template void check_scaled_forces<double>(const kernels::LocalForces<double>&, double, double);

}  // namespace kinema
