#pragma once
// Integration methods as data.
//
// An explicit Runge-Kutta method is its Butcher tableau (a, b, c). A symplectic method is a
// sequence of kicks (v += w h a(x, v, t0 + c h)) and drifts (x += w h v). Adding a method
// means adding a constant here (and listing it in `builtin_methods` to get the fused
// kernel); no kernel is written for it.

#include <array>
#include <span>
#include <string_view>

namespace kinema {

inline constexpr int kMaxStages = 4;

struct ButcherTableau {
  int stages = 0;
  std::array<std::array<double, kMaxStages>, kMaxStages> a{};  // strictly lower triangular
  std::array<double, kMaxStages> b{};
  std::array<double, kMaxStages> c{};
};

enum class OpKind { kick, drift };

struct KickDriftOp {
  OpKind kind = OpKind::kick;
  double weight = 0;  // fraction of h
  double time = 0;    // kicks only: force evaluated at t0 + time * h
};

struct KickDriftScheme {
  int count = 0;
  std::array<KickDriftOp, kMaxStages> ops{};
};

enum class MethodKind { runge_kutta, kick_drift };

struct Method {
  std::string_view name;
  MethodKind kind = MethodKind::runge_kutta;
  int order = 0;  // global order of accuracy for smooth, velocity-independent forces
  ButcherTableau tableau{};
  KickDriftScheme scheme{};

  // Force evaluations per step.
  constexpr int evaluations() const {
    if (kind == MethodKind::runge_kutta) return tableau.stages;
    int kicks = 0;
    for (int i = 0; i < scheme.count; ++i) kicks += scheme.ops[i].kind == OpKind::kick;
    return kicks;
  }
};

inline constexpr Method euler{"euler", MethodKind::runge_kutta, 1, {1, {}, {1}, {0}}, {}};

inline constexpr Method midpoint{
    "midpoint", MethodKind::runge_kutta, 2, {2, {{{}, {0.5}}}, {0, 1}, {0, 0.5}}, {}};

inline constexpr Method heun{
    "heun", MethodKind::runge_kutta, 2, {2, {{{}, {1}}}, {0.5, 0.5}, {0, 1}}, {}};

// Classic RK4. Note k4 = f(x0 + h k3): a[3][2] is 1, not 1/2.
inline constexpr Method rk4{"rk4",
                            MethodKind::runge_kutta,
                            4,
                            {4,
                             {{{}, {0.5}, {0, 0.5}, {0, 0, 1}}},
                             {1.0 / 6, 1.0 / 3, 1.0 / 3, 1.0 / 6},
                             {0, 0.5, 0.5, 1}},
                            {}};

// Semi-implicit Euler as engines ship it: v1 = v0 + h a(x0, v0, t0); x1 = x0 + h v1.
inline constexpr Method symplectic_euler{
    "symplectic_euler",
    MethodKind::kick_drift,
    1,
    {},
    {2, {{{OpKind::kick, 1, 0}, {OpKind::drift, 1, 0}}}}};

// Velocity Verlet (kick-drift-kick). The second kick sees the half-step velocity, so with
// velocity-dependent forces the velocity update is only first order.
inline constexpr Method velocity_verlet{
    "velocity_verlet",
    MethodKind::kick_drift,
    2,
    {},
    {3, {{{OpKind::kick, 0.5, 0}, {OpKind::drift, 1, 0}, {OpKind::kick, 0.5, 1}}}}};

// The methods with a compiled fused kernel, in a fixed order (their index is stable).
inline constexpr std::array<const Method*, 6> builtin_methods = {
    &euler, &midpoint, &heun, &rk4, &symplectic_euler, &velocity_verlet};

// The built-in method of that name; throws kinema::Error listing the known names.
const Method& method_by_name(std::string_view name);

// Index of `method` in builtin_methods when its coefficients equal a built-in's, else -1.
int builtin_index(const Method& method);

// Throws kinema::Error when the method is not a valid explicit method (stages out of
// range, a not strictly lower triangular, non-finite coefficients).
void validate(const Method& method);

}  // namespace kinema
