#include "kinema/stability.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <limits>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "kinema/error.hpp"

namespace kinema {
namespace {

using Matrix = std::array<std::array<double, 2>, 2>;

// A linearly implicit step on the mode: its Jacobian exact where the mode stands for the
// springs' (in_j), else J = [[0, 1], [0, 0]], the forces stepped explicitly.
std::array<double, 2> rosenbrock_step(const RosenbrockScheme& r, double h, double a, double b, std::array<double, 2> y,
                                      bool in_j) {
  const auto f = [&](const std::array<double, 2>& s) { return std::array<double, 2>{s[1], a * s[0] + b * s[1]}; };
  const double g = r.gamma * h, ja = in_j ? a : 0, jb = in_j ? b : 0;
  // W = I - g J, J = [[0, 1], [ja, jb]]; k = W^-1 r by Cramer's rule.
  const double w00 = 1, w01 = -g, w10 = -g * ja, w11 = 1 - g * jb, det = w00 * w11 - w01 * w10;
  std::array<std::array<double, 2>, kMaxRosenbrockStages> k{};
  for (int s = 0; s < r.stages; ++s) {
    std::array<double, 2> stage = y;
    for (int j = 0; j < s; ++j) {
      for (int d = 0; d < 2; ++d) stage[d] += h * r.a[s][j] * k[j][d];
    }
    std::array<double, 2> rhs = f(stage);
    for (int j = 0; j < s; ++j) {
      for (int d = 0; d < 2; ++d) rhs[d] += r.c[s][j] * k[j][d];
    }
    k[s] = {(rhs[0] * w11 - w01 * rhs[1]) / det, (w00 * rhs[1] - w10 * rhs[0]) / det};
  }
  for (int s = 0; s < r.stages; ++s) {
    for (int d = 0; d < 2; ++d) y[d] += h * r.m[s] * k[s][d];
  }
  return y;
}

// One step of size h of `m` on x' = v, v' = a x + b v, from (x, v); `in_j` as ImplicitMode.
std::array<double, 2> one_step(const Method& m, double h, double a, double b, std::array<double, 2> y, bool in_j) {
  const auto f = [&](const std::array<double, 2>& s) { return std::array<double, 2>{s[1], a * s[0] + b * s[1]}; };
  if (m.kind == MethodKind::linearly_implicit) return rosenbrock_step(m.rosenbrock, h, a, b, y, in_j);
  if (m.kind == MethodKind::kick_drift) {
    for (int i = 0; i < m.scheme.count; ++i) {
      const KickDriftOp& op = m.scheme.ops[i];
      if (op.kind == OpKind::kick) y[1] += op.weight * h * f(y)[1];
      else y[0] += op.weight * h * y[1];
    }
    return y;
  }
  const ButcherTableau& t = m.tableau;
  std::array<std::array<double, 2>, kMaxStages> k{};
  for (int s = 0; s < t.stages; ++s) {
    std::array<double, 2> stage = y;
    for (int j = 0; j < s; ++j) {
      for (int d = 0; d < 2; ++d) stage[d] += h * t.a[s][j] * k[j][d];
    }
    k[s] = f(stage);
  }
  for (int s = 0; s < t.stages; ++s) {
    for (int d = 0; d < 2; ++d) y[d] += h * t.b[s] * k[s][d];
  }
  return y;
}

double spectral_radius(Matrix m) {
  // Triangular (the damping mode: v does not see x): the diagonal, without the cancellation
  // the discriminant would suffer next to an eigenvalue of exactly 1.
  if (m[1][0] == 0 || m[0][1] == 0) {
    const double d0 = std::abs(m[0][0]), d1 = std::abs(m[1][1]);
    return std::isnan(d0) || std::isnan(d1) ? std::numeric_limits<double>::quiet_NaN() : std::max(d0, d1);
  }
  // Entries past 1e150 (a step far past the stable one) would overflow the determinant:
  // the radius of the matrix scaled by a power of two, scaled back.
  const double largest = std::max({std::abs(m[0][0]), std::abs(m[0][1]), std::abs(m[1][0]), std::abs(m[1][1])});
  if (largest > 1e150 && std::isfinite(largest)) {
    const int shift = std::ilogb(largest);
    for (auto& row : m) {
      for (double& x : row) x = std::scalbn(x, -shift);
    }
    return std::scalbn(spectral_radius(m), shift);
  }
  const double trace = m[0][0] + m[1][1], det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
  const double disc = trace * trace - 4 * det;
  if (disc < 0) return std::sqrt(std::abs(det));
  const double root = std::sqrt(disc);
  return std::max(std::abs(trace + root), std::abs(trace - root)) / 2;
}

double radius(const Method& m, double h, double a, double b, bool in_j = true) {
  const auto c0 = one_step(m, h, a, b, {1, 0}, in_j), c1 = one_step(m, h, a, b, {0, 1}, in_j);
  return spectral_radius({{{c0[0], c1[0]}, {c0[1], c1[1]}}});
}

// Is a step of h stable on the mode (a, b)? Rounding may lift a radius of exactly 1.
bool stable(const Method& m, double h, double a, double b, bool in_j) { return radius(m, h, a, b, in_j) <= 1 + 1e-13; }

// The mode (a, b) of x'' = a x + b v an estimate stands for (see stability.hpp).
std::pair<double, double> mode_of(const StiffnessEstimate& e) {
  const double r = e.magnitude;
  if (e.angle < 1e-3) return {0, -r};
  return {-r * r, -2 * r * std::cos(e.angle)};
}

// The largest h up to which every step is stable on the mode (a, b) whose rate is `rate`:
// a scan of h rate from 1e-4 to 100 in steps of 0.2%, then bisection at the first failure.
double stable_edge(const Method& m, double rate, double a, double b, bool in_j = true) {
  double good = 0, z = 1e-4;
  while (z < 100 && stable(m, z / rate, a, b, in_j)) good = z, z *= 1.002;
  if (z >= 100) return std::numeric_limits<double>::infinity();
  double bad = z;
  for (int i = 0; i < 60 && good > 0; ++i) {
    const double mid = (good + bad) / 2;
    (stable(m, mid / rate, a, b, in_j) ? good : bad) = mid;
  }
  return good / rate;
}

// A reproducible start vector with every component nonzero.
double start_component(std::size_t i) {
  std::uint64_t z = (i + 1) * 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return 0.5 + double((z ^ (z >> 31)) >> 11) * 0x1p-53;
}

double norm(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s);
}

double dot(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

// With u, J u and J^2 u: once u lies in the dominant invariant subspace of J (one real
// eigenvalue, or a pair of them, real or complex conjugate), J^2 u = p J u + q u, and the
// roots of x^2 - p x - q are those eigenvalues. p and q by least squares; the root of the
// larger modulus.
std::complex<double> dominant_root(const std::vector<double>& u, const std::vector<double>& w1,
                                   const std::vector<double>& w2) {
  const double a11 = dot(w1, w1), a12 = dot(w1, u), a22 = dot(u, u);
  const double r1 = dot(w1, w2), r2 = dot(u, w2);
  const double det = a11 * a22 - a12 * a12;
  // J u parallel to u (to the finite differences' accuracy): one real eigenvalue.
  if (!(det > 1e-8 * a11 * a22)) return a22 > 0 ? a12 / a22 : 0.0;
  const double p = (r1 * a22 - r2 * a12) / det, q = (a11 * r2 - a12 * r1) / det;
  const std::complex<double> root = std::sqrt(std::complex<double>(p * p + 4 * q, 0));
  const std::complex<double> x1 = (p + root) / 2.0, x2 = (p - root) / 2.0;
  return std::abs(x1) >= std::abs(x2) ? x1 : x2;
}

// The dominant eigenvalue of a small dense n x n matrix (row-major), and a real vector in
// its dominant invariant subspace: power iteration with the pair fit, run long (it is cheap
// at this size) so that close eigenvalues at the top separate.
std::pair<std::complex<double>, std::vector<double>> dominant_of(const std::vector<double>& h, std::size_t n) {
  const auto times = [&](const std::vector<double>& x) {
    std::vector<double> out(n, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = 0; j < n; ++j) out[i] += h[i * n + j] * x[j];
    }
    return out;
  };
  std::vector<double> u(n);
  for (std::size_t i = 0; i < n; ++i) u[i] = start_component(i);
  std::complex<double> root = 0;
  for (int k = 0; k < 4000; ++k) {
    const double un = norm(u);
    if (!(un > 0) || !std::isfinite(un)) break;
    for (double& c : u) c /= un;
    const std::vector<double> w1 = times(u), w2 = times(w1);
    root = dominant_root(u, w1, w2);
    u = w2;
  }
  const double un = norm(u);
  if (un > 0 && std::isfinite(un)) {
    for (double& c : u) c /= un;
  }
  return {root, u};
}

// The state arrays of a set, and which of them are position-like (balance scales those).
template <class T>
std::array<T*, 6> state_arrays(ParticleSet<T>& b) {
  return {b.px(), b.py(), b.pz(), b.vx(), b.vy(), b.vz()};
}
template <class T>
std::array<T*, 13> state_arrays(RigidBodySet<T>& b) {
  return {b.position_data(0), b.position_data(1), b.position_data(2), b.velocity_data(0), b.velocity_data(1),
          b.velocity_data(2), b.q(0), b.q(1), b.q(2), b.q(3), b.l(0), b.l(1), b.l(2)};
}
constexpr bool position_like(int components, int c) { return c < 3 || (components == 13 && c >= 6 && c < 10); }

// f(y) of a set, y its state in C component blocks of `n` each (particles: x, v; rigid
// bodies: x, v, q, L), f from `rates`, which writes the C rates of a set (padded each).
template <class T, class Set, int C>
class Derivative {
 public:
  using Rates = std::function<void(const Set&, T* const out[C])>;
  Derivative(const Set& bodies, Rates rates) : work_(bodies), rates_(std::move(rates)), n_(bodies.size()) {
    for (auto& a : out_) a.resize(work_.padded_size());
  }

  static constexpr int components = C;
  using value_type = T;
  std::size_t size() const { return C * n_; }
  std::size_t count() const { return n_; }
  std::vector<double> state() {
    std::vector<double> y(size());
    const auto arrays = state_arrays(work_);
    for (int c = 0; c < C; ++c) std::copy(arrays[c], arrays[c] + n_, y.begin() + std::ptrdiff_t(c * n_));
    return y;
  }
  std::vector<double> operator()(const std::vector<double>& y) {
    const auto arrays = state_arrays(work_);
    for (int c = 0; c < C; ++c) {
      for (std::size_t i = 0; i < n_; ++i) arrays[c][i] = T(y[c * n_ + i]);
    }
    T* out[C];
    for (int c = 0; c < C; ++c) out[c] = out_[c].data();
    rates_(work_, out);
    ++evaluations;
    std::vector<double> f(size());
    for (int c = 0; c < C; ++c) std::copy(out[c], out[c] + n_, f.begin() + std::ptrdiff_t(c * n_));
    return f;
  }
  int evaluations = 0;

 private:
  Set work_;
  Rates rates_;
  std::size_t n_;
  std::array<std::vector<T>, C> out_;
};

// J u ~ (f(y + eps u) - f(y)) / eps at the bodies' state y, with positions scaled by
// `position_scale` (D J D^-1, D = diag(s, 1): see balance). eps is scaled so that the largest
// component of eps u moves y by about sqrt(machine epsilon) of its size: the usual balance of
// truncation and rounding, for every component that matters.
template <class D>
class JacobianProducts {
 public:
  explicit JacobianProducts(D& f) : f_(f), y_(f.state()), f0_(f(y_)) {
    for (double c : y_) y_scale_ = std::max(y_scale_, std::abs(c));
  }

  std::size_t size() const { return y_.size(); }
  std::vector<double> times(const std::vector<double>& u) {
    double largest = 0;
    for (double c : u) largest = std::max(largest, std::abs(c));
    const double eps = std::sqrt(double(std::numeric_limits<typename D::value_type>::epsilon())) * y_scale_ / std::max(largest, 1e-300);
    std::vector<double> shifted = y_;
    for (std::size_t i = 0; i < y_.size(); ++i) shifted[i] += eps * u[i];
    std::vector<double> ju = f_(shifted);
    for (std::size_t i = 0; i < y_.size(); ++i) ju[i] = (ju[i] - f0_[i]) / eps;
    return ju;
  }
  std::vector<double> balanced_times(std::vector<double> u) {
    scale_positions(u, 1 / position_scale);
    std::vector<double> w = times(u);
    scale_positions(w, position_scale);
    return w;
  }

  double position_scale = 1;

 private:
  void scale_positions(std::vector<double>& u, double by) const {
    const std::size_t n = f_.count();
    for (int c = 0; c < D::components; ++c) {
      if (!position_like(D::components, c)) continue;
      for (std::size_t i = c * n; i < (c + 1) * n; ++i) u[i] *= by;
    }
  }

  D& f_;
  std::vector<double> y_, f0_;
  double y_scale_ = 1;
};

// Positions and velocities differ in scale by the frequencies themselves, which makes J
// far from normal ([0 I; -w^2 0]) and Krylov estimates erratic. Scaling positions by a
// first guess s of |lambda| (a few power steps) balances it: D J D^-1 with D = diag(s, 1)
// has J's eigenvalues and, for an oscillation, is nearly skew-symmetric.
template <class D>
void balance(JacobianProducts<D>& jacobian) {
  std::vector<double> u(jacobian.size());
  for (std::size_t i = 0; i < u.size(); ++i) u[i] = start_component(i);
  for (int k = 0; k < 8; ++k) {
    const double un = norm(u);
    if (!(un > 0) || !std::isfinite(un)) break;
    for (double& c : u) c /= un;
    const std::vector<double> w1 = jacobian.times(u), w2 = jacobian.times(w1);
    const double guess = std::abs(dominant_root(u, w1, w2));
    if (guess > 0 && std::isfinite(guess)) jacobian.position_scale = guess;
    u = w2;
  }
}

// One cycle of restarted Arnoldi: up to m products from v build an orthonormal Krylov basis
// and the projection H = V^T J V, whose dominant eigenvalue approaches J's far faster than
// plain power iteration does where the top of the spectrum is dense (a cloth's modes). `done`
// counts the products, at most `budget` of them. Returns H's dominant eigenvalue; v becomes
// the basis combination in H's dominant subspace, the next cycle's start.
template <class D>
std::complex<double> arnoldi_cycle(JacobianProducts<D>& jacobian, std::vector<double>& v, int m, int& done,
                                   int budget) {
  std::vector<std::vector<double>> basis{v};
  std::vector<double> h(std::size_t(m * m), 0.0);
  int k = 0;
  while (k < m && done < budget) {
    std::vector<double> w = jacobian.balanced_times(basis[std::size_t(k)]);
    ++done;
    const double before = norm(w);
    for (int pass = 0; pass < 2; ++pass) {  // Gram-Schmidt twice: orthogonal to rounding
      for (int i = 0; i <= k; ++i) {
        const double c = dot(basis[std::size_t(i)], w);
        h[std::size_t(i * m + k)] += c;
        for (std::size_t j = 0; j < w.size(); ++j) w[j] -= c * basis[std::size_t(i)][j];
      }
    }
    const double beta = norm(w);
    ++k;
    if (!(beta > 1e-10 * before) || k == m) break;  // an invariant subspace, or the basis is full
    h[std::size_t(k * m + k - 1)] = beta;
    for (double& c : w) c /= beta;
    basis.push_back(std::move(w));
  }
  std::vector<double> hk(std::size_t(k * k));
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j < k; ++j) hk[std::size_t(i * k + j)] = h[std::size_t(i * m + j)];
  }
  const auto [root, combination] = dominant_of(hk, std::size_t(k));
  std::fill(v.begin(), v.end(), 0.0);
  for (int i = 0; i < k; ++i) {
    for (std::size_t j = 0; j < v.size(); ++j) v[j] += combination[std::size_t(i)] * basis[std::size_t(i)][j];
  }
  return root;
}


template <class D>
StiffnessEstimate dominant_mode(D& f, int iterations) {
  StiffnessEstimate e;
  if (f.size() == 0) return e;
  JacobianProducts<D> jacobian(f);
  balance(jacobian);
  // Krylov bases of up to 20 vectors, fewer when they would pass 512 MiB.
  const std::size_t memory_cap = std::size_t(512) << 20;
  const int most = std::min(iterations, 20);
  const int m = int(std::clamp<std::size_t>(memory_cap / (8 * jacobian.size()), std::size_t(std::min(2, most)),
                                            std::size_t(most)));
  std::vector<double> v(jacobian.size());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = start_component(i);
  std::complex<double> dominant = 0;
  for (int done = 0; done < iterations;) {
    // A cycle the budget would cut short is not started once there is an estimate: a basis of
    // one or two vectors may not hold the dominant pair, and its answer would replace a
    // better one.
    if (done > 0 && iterations - done < m) break;
    const double vn = norm(v);
    if (!(vn > 0) || !std::isfinite(vn)) break;
    for (double& c : v) c /= vn;
    dominant = arnoldi_cycle(jacobian, v, m, done, iterations);
  }
  e.evaluations = f.evaluations;
  e.magnitude = std::abs(dominant);

  // A mode that grows (Re lambda > 0: a body falling away from a saddle, or an oscillation
  // whose finite differences lean that way) is judged as its decaying mirror: no step keeps
  // a growing mode bounded, and a method's stability is about the ones that should be.
  e.angle = std::atan2(std::abs(dominant.imag()), std::abs(dominant.real()));
  return e;
}

}  // namespace

template <class T>
StiffnessEstimate estimate_stiffness(const ParticleSet<T>& bodies,
                                     const std::type_identity_t<AccelerationFn<T>>& accelerations, int iterations) {
  if (iterations < 1) throw Error("estimate_stiffness: iterations must be >= 1");
  // The position rates are the velocities.
  const auto rates = [&](const ParticleSet<T>& set, T* const out[6]) {
    for (int d = 0; d < 3; ++d) {
      const T* v = d == 0 ? set.vx() : d == 1 ? set.vy() : set.vz();
      std::copy(v, v + set.padded_size(), out[d]);
    }
    accelerations(set, out + 3);
  };
  Derivative<T, ParticleSet<T>, 6> f(bodies, rates);
  return dominant_mode(f, iterations);
}

template <class T>
StiffnessEstimate estimate_stiffness(const RigidBodySet<T>& bodies,
                                     const std::type_identity_t<RigidRatesFn<T>>& rates, int iterations) {
  if (iterations < 1) throw Error("estimate_stiffness: iterations must be >= 1");
  Derivative<T, RigidBodySet<T>, 13> f(bodies, rates);
  return dominant_mode(f, iterations);
}

namespace {

// Where the mode's rate squared overflows double (|lambda| past 1e154): a step h on the mode
// at rate r is similar, by a change of scale of v, to a step h r on the mode at rate 1, with
// the same growth. Other rates keep the direct form (and its bits).
bool rate_squared_overflows(const StiffnessEstimate& e) { return !std::isfinite(e.magnitude * e.magnitude); }

std::pair<double, double> unit_mode_of(StiffnessEstimate e) {
  e.magnitude = 1;
  return mode_of(e);
}

// A magnitude that is NaN would pass for 0 (no mode: every step stable).
void check_magnitude(const StiffnessEstimate& e, const char* who) {
  if (std::isnan(e.magnitude)) throw Error(std::string(who) + ": the estimate's magnitude is NaN");
}

}  // namespace

double largest_stable_step(const Method& method, const StiffnessEstimate& e, ImplicitMode mode) {
  check_magnitude(e, "largest_stable_step");
  if (!(e.magnitude > 0)) return std::numeric_limits<double>::infinity();
  const bool in_j = mode == ImplicitMode::in_jacobian;
  if (rate_squared_overflows(e)) {
    const auto [a, b] = unit_mode_of(e);
    return stable_edge(method, 1, a, b, in_j) / e.magnitude;
  }
  const auto [a, b] = mode_of(e);
  return stable_edge(method, e.magnitude, a, b, in_j);
}

double growth_per_step(const Method& method, const StiffnessEstimate& e, double h, ImplicitMode mode) {
  check_magnitude(e, "growth_per_step");
  if (!(e.magnitude > 0)) return 1;
  const bool in_j = mode == ImplicitMode::in_jacobian;
  double growth = 0;
  if (rate_squared_overflows(e)) {
    const auto [a, b] = unit_mode_of(e);
    growth = radius(method, h * e.magnitude, a, b, in_j);
  } else {
    const auto [a, b] = mode_of(e);
    growth = radius(method, h, a, b, in_j);
  }
  return std::isnan(growth) ? std::numeric_limits<double>::infinity() : growth;  // the step's entries overflowed
}

StabilityLimits stability_limits(const Method& method) {
  return {stable_edge(method, 1, 0, -1), stable_edge(method, 1, -1, 0)};
}

template StiffnessEstimate estimate_stiffness(const ParticleSet<float>&, const AccelerationFn<float>&, int);
template StiffnessEstimate estimate_stiffness(const ParticleSet<double>&, const AccelerationFn<double>&, int);
template StiffnessEstimate estimate_stiffness(const RigidBodySet<float>&, const RigidRatesFn<float>&, int);
template StiffnessEstimate estimate_stiffness(const RigidBodySet<double>&, const RigidRatesFn<double>&, int);

}  // namespace kinema
