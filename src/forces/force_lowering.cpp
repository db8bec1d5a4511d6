#include "forces/force_lowering.hpp"

#include <algorithm>
#include <cmath>

#include "core/text.hpp"
#include "forces/force_terms.hpp"
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
std::array<T, 3> in_precision(const Vec3<double>& v) {
  return {in_precision<T>(v[0]), in_precision<T>(v[1]), in_precision<T>(v[2])};
}

template <class T>
kernels::LocalForces<T> lower_local(const LocalSums& s) {
  kernels::LocalForces<T> out;
  out.central_count = std::min(s.central_count, kMaxCentralTerms);  // a ForceModel holds no more
  for (int c = 0; c < out.central_count; ++c) {
    out.center[c] = in_precision<T>(s.center[c]);
    out.mu[c] = in_precision<T>(s.mu[c]);
  }
  out.gravity = in_precision<T>(s.gravity);
  out.constant_force = in_precision<T>(s.push);
  for (int d = 0; d < 3; ++d) {
    out.anchor[d] = s.spring_k > 0 ? in_precision<T>(s.weighted_anchor[d] / s.spring_k) : T(0);
  }
  out.spring_k = in_precision<T>(s.spring_k);
  out.linear = in_precision<T>(s.linear);
  out.quadratic = in_precision<T>(s.quadratic);
  return out;
}

template <class T>
kernels::RotationalForces<T> lower_rotational(const LocalSums& s) {
  kernels::RotationalForces<T> out;
  out.point_count = std::min(s.point_count, kMaxPointForces);
  for (int p = 0; p < out.point_count; ++p) {
    out.point[p] = in_precision<T>(s.point[p]);
    out.force[p] = in_precision<T>(s.point_force[p]);
  }
  out.torque = in_precision<T>(s.torque);
  out.angular_drag = in_precision<T>(s.angular_drag);
  return out;
}

}  // namespace

template <class T>
LoweredForces<T> lower_forces(std::span<const LocalTerm> terms) {
  const LocalSums sums = sum_terms(terms);
  LoweredForces<T> out;
  out.rigid = lower_local<T>(sums);
  out.particle = out.rigid;
  out.particle.constant_force = {};
  out.rotation = lower_rotational<T>(sums);
  return out;
}

template <class T>
void check_scaled_forces(const kernels::LocalForces<T>& f, const CoupledForces<T>& coupled, T scale, T h) {
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
  if (coupled.nbody && !std::isfinite(scale * T(coupled.nbody->G))) {
    throw Error("step size h = " + shortest_text(h) + " times nbody.G overflows " + type_name<T>() +
                "; take a smaller step");
  }
}

template <class T>
void check_scaled_parameters(const BodyParameters<T>& own, const kernels::LocalForces<T>& f, T scale, T h) {
  if (!own.any()) return;
  const T factor = own.largest(BodyParameter::gravity_factor);
  bool finite = std::isfinite(own.largest(BodyParameter::linear_damping) * scale) &&
                std::isfinite(own.largest(BodyParameter::angular_damping) * h);
  for (int d = 0; d < 3; ++d) finite = finite && std::isfinite(factor * (f.gravity[d] * scale));
  if (!finite) {
    throw Error("step size h = " + shortest_text(h) + " times the bodies' gravity factors or damping rates overflows " +
                type_name<T>() + "; take a smaller step");
  }
}

template LoweredForces<float> lower_forces<float>(std::span<const LocalTerm>);
template LoweredForces<double> lower_forces<double>(std::span<const LocalTerm>);
template void check_scaled_forces<float>(const kernels::LocalForces<float>&, const CoupledForces<float>&, float,
                                         float);
template void check_scaled_forces<double>(const kernels::LocalForces<double>&, const CoupledForces<double>&, double,
                                          double);
template void check_scaled_parameters<float>(const BodyParameters<float>&, const kernels::LocalForces<float>&, float,
                                             float);
template void check_scaled_parameters<double>(const BodyParameters<double>&, const kernels::LocalForces<double>&,
                                              double, double);

}  // namespace kinema
