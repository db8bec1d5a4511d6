// The baselines, on the same bodies and forces as the kinema suites, built for baseline
// x86-64 like any portable binary:
//  - a textbook array-of-structs RK4 with a temporary state per stage;
//  - Boost.Odeint runge_kutta4 over std::vector (positions then velocities).
#include <benchmark/benchmark.h>

#include <boost/numeric/odeint.hpp>
#include <cmath>
#include <vector>

#include "bench_scene.hpp"

namespace kinema::bench {
namespace {

// The textbook particle system (as in Witkin and Baraff's course notes): particles as
// structs with a force accumulator, the state gathered into one flat vector, and RK4 built
// from whole-vector operations, each stage a pass writing its own temporary. The
// temporaries are allocated once, not per step (kinder than the notes).
template <class T>
struct Particle {
  T x[3], v[3], f[3], m;
};

template <class T>
class NaiveSystem {
 public:
  explicit NaiveSystem(std::size_t n) : particles_(n) {
    const ParticleSet<T>& soa = cached_particles<T>(n);
    for (std::size_t i = 0; i < n; ++i) {
      Particle<T>& p = particles_[i];
      p.x[0] = soa.px()[i], p.x[1] = soa.py()[i], p.x[2] = soa.pz()[i];
      p.v[0] = soa.vx()[i], p.v[1] = soa.vy()[i], p.v[2] = soa.vz()[i];
      p.m = T(1) / soa.inv_mass()[i];
    }
    for (auto* v : {&x0_, &tmp_, &k1_, &k2_, &k3_, &k4_}) v->resize(6 * n);
  }

  void rk4_step(T h) {
    get_state(x0_);
    derivative(k1_);
    add_scaled(x0_, k1_, h / 2, tmp_);
    set_state(tmp_);
    derivative(k2_);
    add_scaled(x0_, k2_, h / 2, tmp_);
    set_state(tmp_);
    derivative(k3_);
    add_scaled(x0_, k3_, h, tmp_);
    set_state(tmp_);
    derivative(k4_);
    for (std::size_t i = 0; i < x0_.size(); ++i) {
      x0_[i] += h / 6 * (k1_[i] + 2 * k2_[i] + 2 * k3_[i] + k4_[i]);
    }
    set_state(x0_);
  }

  bool finite() const {
    for (const auto& p : particles_) {
      if (!std::isfinite(p.x[0] + p.x[1] + p.x[2] + p.v[0] + p.v[1] + p.v[2])) return false;
    }
    return true;
  }

 private:
  void get_state(std::vector<T>& dst) const {
    for (std::size_t i = 0; i < particles_.size(); ++i) {
      for (int c = 0; c < 3; ++c) dst[6 * i + c] = particles_[i].x[c];
      for (int c = 0; c < 3; ++c) dst[6 * i + 3 + c] = particles_[i].v[c];
    }
  }
  void set_state(const std::vector<T>& src) {
    for (std::size_t i = 0; i < particles_.size(); ++i) {
      for (int c = 0; c < 3; ++c) particles_[i].x[c] = src[6 * i + c];
      for (int c = 0; c < 3; ++c) particles_[i].v[c] = src[6 * i + 3 + c];
    }
  }
  void compute_forces() {
    for (auto& p : particles_) {
      for (int c = 0; c < 3; ++c) {
        p.f[c] = (c == 1 ? p.m * T(kGravity) : T(0)) - T(kDrag) * p.v[c] - T(kSpring) * p.x[c];
      }
    }
  }
  void derivative(std::vector<T>& dst) {
    for (auto& p : particles_) p.f[0] = p.f[1] = p.f[2] = 0;
    compute_forces();
    for (std::size_t i = 0; i < particles_.size(); ++i) {
      for (int c = 0; c < 3; ++c) dst[6 * i + c] = particles_[i].v[c];
      for (int c = 0; c < 3; ++c) dst[6 * i + 3 + c] = particles_[i].f[c] / particles_[i].m;
    }
  }
  static void add_scaled(const std::vector<T>& a, const std::vector<T>& b, T s,
                         std::vector<T>& out) {
    for (std::size_t i = 0; i < a.size(); ++i) out[i] = a[i] + s * b[i];
  }

  std::vector<Particle<T>> particles_;
  std::vector<T> x0_, tmp_, k1_, k2_, k3_, k4_;
};

template <class T>
void naive_aos_rk4(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  NaiveSystem<T> system(n);
  system.rk4_step(T(kDt));  // warm, as for the others
  for (auto _ : state) {
    system.rk4_step(T(kDt));
    benchmark::ClobberMemory();
  }
  if (!system.finite()) state.SkipWithError("state is not finite after the run");
  report_body_steps(state, double(n), particle_step_bytes<T>());
}

// Odeint's state: [x(3n), v(3n)], inverse masses alongside. The derivative loops over bodies,
// then components, as one would write it: a flat loop indexing masses by i / 3 vectorizes
// worse, and the baseline should be the fair one (bench/README.md has the figures).
template <class T>
struct OdeintSystem {
  const std::vector<T>* inv_mass;
  void operator()(const std::vector<T>& s, std::vector<T>& ds, double) const {
    const std::size_t n = inv_mass->size(), n3 = 3 * n;
    for (std::size_t b = 0; b < n; ++b) {
      const T m = (*inv_mass)[b];
      for (std::size_t d = 0; d < 3; ++d) {
        const std::size_t i = 3 * b + d;
        const T x = s[i], v = s[n3 + i];
        ds[i] = v;
        ds[n3 + i] = (d == 1 ? T(kGravity) : T(0)) + m * (-T(kSpring) * x - T(kDrag) * v);
      }
    }
  }
};

template <class T>
void odeint_rk4(benchmark::State& state) {
  const auto n = std::size_t(state.range(0));
  const ParticleSet<T>& soa = cached_particles<T>(n);
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
  stepper.do_step(system, s, t, T(kDt));  // warm: Odeint allocates its temporaries here
  t += T(kDt);
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
