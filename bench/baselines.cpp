// The baselines, on the same bodies and forces as the kinema suites:
//  - a textbook array-of-structs RK4 with a temporary state per stage;
//  - Boost.Odeint runge_kutta4 over std::vector (positions then velocities).
#include <benchmark/benchmark.h>

#include <boost/numeric/odeint.hpp>
#include <cmath>
#include <vector>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

template <class T>
struct Particle {
  T x[3], v[3], inv_mass;
};

template <class T>
struct Derivative {
  T dx[3], dv[3];
};

template <class T>
Derivative<T> derivative(const Particle<T>& p) {
  Derivative<T> d;
  for (int i = 0; i < 3; ++i) {
    const T force = -T(kSpring) * p.x[i] - T(kDrag) * p.v[i];
    d.dx[i] = p.v[i];
    d.dv[i] = (i == 1 ? T(kGravity) : T(0)) + p.inv_mass * force;
  }
  return d;
}

template <class T>
Particle<T> offset(const Particle<T>& p, const Derivative<T>& d, T h) {
  Particle<T> q = p;
  for (int i = 0; i < 3; ++i) q.x[i] += h * d.dx[i], q.v[i] += h * d.dv[i];
  return q;
}

// The textbook RK4: per-stage temporaries for the whole set, one pass per stage.
template <class T>
void naive_rk4_step(std::vector<Particle<T>>& ps, std::vector<Derivative<T>> (&k)[4], T h) {
  const std::size_t n = ps.size();
  for (std::size_t i = 0; i < n; ++i) k[0][i] = derivative(ps[i]);
  for (std::size_t i = 0; i < n; ++i) k[1][i] = derivative(offset(ps[i], k[0][i], h / 2));
  for (std::size_t i = 0; i < n; ++i) k[2][i] = derivative(offset(ps[i], k[1][i], h / 2));
  for (std::size_t i = 0; i < n; ++i) k[3][i] = derivative(offset(ps[i], k[2][i], h));
  for (std::size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      ps[i].x[c] += h / 6 * (k[0][i].dx[c] + 2 * k[1][i].dx[c] + 2 * k[2][i].dx[c] + k[3][i].dx[c]);
      ps[i].v[c] += h / 6 * (k[0][i].dv[c] + 2 * k[1][i].dv[c] + 2 * k[2][i].dv[c] + k[3][i].dv[c]);
    }
  }
}

template <class T>
std::vector<Particle<T>> aos_bodies(std::size_t n) {
  const ParticleSet<T> soa = make_particles<T>(bench_scene(n));
  std::vector<Particle<T>> ps(n);
  for (std::size_t i = 0; i < n; ++i) {
    ps[i] = {{soa.px()[i], soa.py()[i], soa.pz()[i]},
             {soa.vx()[i], soa.vy()[i], soa.vz()[i]},
             soa.inv_mass()[i]};
  }
  return ps;
}

template <class T>
void naive_aos_rk4(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  std::vector<Particle<T>> ps = aos_bodies<T>(n);
  std::vector<Derivative<T>> k[4] = {std::vector<Derivative<T>>(n), std::vector<Derivative<T>>(n),
                                     std::vector<Derivative<T>>(n), std::vector<Derivative<T>>(n)};
  for (auto _ : state) {
    naive_rk4_step(ps, k, T(kDt));
    benchmark::ClobberMemory();
  }
  for (const auto& p : ps) {
    if (!std::isfinite(p.x[0] + p.x[1] + p.x[2] + p.v[0] + p.v[1] + p.v[2])) {
      state.SkipWithError("state is not finite after the run");
      break;
    }
  }
  report_body_steps(state, double(n), particle_step_bytes<T>());
}

// Odeint's state: [x(3n), v(3n)], inverse masses alongside.
template <class T>
struct OdeintSystem {
  const std::vector<T>* inv_mass;
  void operator()(const std::vector<T>& s, std::vector<T>& ds, double) const {
    const std::size_t n3 = s.size() / 2;
    for (std::size_t i = 0; i < n3; ++i) {
      const T x = s[i], v = s[n3 + i];
      ds[i] = v;
      ds[n3 + i] = (i % 3 == 1 ? T(kGravity) : T(0)) +
                   (*inv_mass)[i / 3] * (-T(kSpring) * x - T(kDrag) * v);
    }
  }
};

template <class T>
void odeint_rk4(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  const ParticleSet<T> soa = make_particles<T>(bench_scene(n));
  std::vector<T> s(6 * n), inv_mass(n);
  for (std::size_t i = 0; i < n; ++i) {
    s[3 * i] = soa.px()[i], s[3 * i + 1] = soa.py()[i], s[3 * i + 2] = soa.pz()[i];
    s[3 * n + 3 * i] = soa.vx()[i], s[3 * n + 3 * i + 1] = soa.vy()[i];
    s[3 * n + 3 * i + 2] = soa.vz()[i];
    inv_mass[i] = soa.inv_mass()[i];
  }
  boost::numeric::odeint::runge_kutta4<std::vector<T>, T, std::vector<T>, T> stepper;
  const OdeintSystem<T> system{&inv_mass};
  T t = 0;
  for (auto _ : state) {
    stepper.do_step(system, s, t, T(kDt));
    t += T(kDt);
    benchmark::ClobberMemory();
  }
  for (T x : s) {
    if (!std::isfinite(x)) {
      state.SkipWithError("state is not finite after the run");
      break;
    }
  }
  report_body_steps(state, double(n), particle_step_bytes<T>());
}

void register_all() {
  const std::int64_t sizes[] = {1 << 10, 1 << 14, 100000, 1 << 20, 1 << 22};
  auto* nf = benchmark::RegisterBenchmark("naive_aos/rk4/float", naive_aos_rk4<float>);
  auto* nd = benchmark::RegisterBenchmark("naive_aos/rk4/double", naive_aos_rk4<double>);
  auto* of = benchmark::RegisterBenchmark("odeint/rk4/float", odeint_rk4<float>);
  auto* od = benchmark::RegisterBenchmark("odeint/rk4/double", odeint_rk4<double>);
  for (auto* b : {nf, nd, of, od}) {
    for (std::int64_t n : sizes) b->Arg(n);
    b->UseRealTime()->Unit(benchmark::kMicrosecond);
  }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace kinema::bench
