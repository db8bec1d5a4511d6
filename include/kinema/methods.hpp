#pragma once
// Integration methods as data.
//
// An explicit Runge-Kutta method is its Butcher tableau (a, b, c). A symplectic method is a
// sequence of kicks (v += w h a(x, v, t0 + c h)) and drifts (x += w h v). A linearly
// implicit method (Rosenbrock-W) solves a linear system per stage with the springs'
// Jacobian (see RosenbrockScheme). Adding a method
// means adding a constant here (and listing it in `builtin_methods` to get the fused
// kernel, or in `staged_methods`); no kernel is written for it. An embedded pair also gives
// the weights of a second, lower-order solution: their difference estimates the error.

#include <array>
#include <span>
#include <string_view>

namespace kinema {

inline constexpr int kMaxStages = 7;

struct ButcherTableau {
  int stages = 0;
  std::array<std::array<double, kMaxStages>, kMaxStages> a{};  // strictly lower triangular
  std::array<double, kMaxStages> b{};
  std::array<double, kMaxStages> c{};
  std::array<double, kMaxStages> b_hat{};  // embedded weights; all zero without a pair

  // The last stage is evaluated at the new solution (last row of a = b, c = 1): an accepted
  // step's last acceleration is the next step's first.
  constexpr bool first_same_as_last() const {
    return stages > 1 && c[stages - 1] == 1 && a[stages - 1] == b;
  }
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

// For stiff springs: with y = (x, v), F(t, y) = (v, a) and J the springs' Jacobian of F,
// each stage solves (I - gamma h J) k_s = F(t0 + time_s h, y0 + h sum_j a_sj k_j) + sum_j c_sj k_j
// and y1 = y0 + h sum_s m_s k_s. Every other force (local terms, callbacks, applied forces,
// N-body gravity) is explicit in F: an IMEX step. A W-method keeps its order with any J, so
// J may leave out the damping's dependence on positions and, under compression, the
// springs' geometric stiffness (src/step/README.md).
inline constexpr int kMaxRosenbrockStages = 2;
struct RosenbrockScheme {
  int stages = 0;
  double gamma = 0;
  std::array<std::array<double, kMaxRosenbrockStages>, kMaxRosenbrockStages> a{}, c{};  // strictly lower
  std::array<double, kMaxRosenbrockStages> m{}, time{};
};

enum class MethodKind { runge_kutta, kick_drift, linearly_implicit };

struct Method {
  std::string_view name;
  MethodKind kind = MethodKind::runge_kutta;
  int order = 0;  // global order of accuracy for smooth, velocity-independent forces
  ButcherTableau tableau{};
  KickDriftScheme scheme{};
  int embedded_order = 0;  // order of the b_hat solution; 0: no embedded pair
  RosenbrockScheme rosenbrock{};

  // Force evaluations per step (an implicit method's linear solves come besides).
  constexpr int evaluations() const {
    if (kind == MethodKind::runge_kutta) return tableau.stages;
    if (kind == MethodKind::linearly_implicit) return rosenbrock.stages;
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

// Bogacki-Shampine 3(2): third order, with a second-order embedded solution; FSAL.
inline constexpr Method bs3{"bs3",
                            MethodKind::runge_kutta,
                            3,
                            {4,
                             {{{}, {0.5}, {0, 0.75}, {2.0 / 9, 1.0 / 3, 4.0 / 9}}},
                             {2.0 / 9, 1.0 / 3, 4.0 / 9, 0},
                             {0, 0.5, 0.75, 1},
                             {7.0 / 24, 0.25, 1.0 / 3, 0.125}},
                            {},
                            2};

// Dormand-Prince 5(4): fifth order, with a fourth-order embedded solution; FSAL.
inline constexpr Method dopri5{
    "dopri5",
    MethodKind::runge_kutta,
    5,
    {7,
     {{{},
       {1.0 / 5},
       {3.0 / 40, 9.0 / 40},
       {44.0 / 45, -56.0 / 15, 32.0 / 9},
       {19372.0 / 6561, -25360.0 / 2187, 64448.0 / 6561, -212.0 / 729},
       {9017.0 / 3168, -355.0 / 33, 46732.0 / 5247, 49.0 / 176, -5103.0 / 18656},
       {35.0 / 384, 0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84}}},
     {35.0 / 384, 0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84, 0},
     {0, 1.0 / 5, 3.0 / 10, 4.0 / 5, 8.0 / 9, 1, 1},
     {5179.0 / 57600, 0, 7571.0 / 16695, 393.0 / 640, -92097.0 / 339200, 187.0 / 2100, 1.0 / 40}},
    {},
    4};

// Butcher's sixth-order method in seven stages (rational coefficients), fixed step.
inline constexpr Method rk6{"rk6",
                            MethodKind::runge_kutta,
                            6,
                            {7,
                             {{{},
                               {1.0 / 3},
                               {0, 2.0 / 3},
                               {1.0 / 12, 1.0 / 3, -1.0 / 12},
                               {-1.0 / 16, 9.0 / 8, -3.0 / 16, -3.0 / 8},
                               {0, 9.0 / 8, -3.0 / 8, -3.0 / 4, 0.5},
                               {9.0 / 44, -9.0 / 11, 63.0 / 44, 18.0 / 11, 0, -16.0 / 11}}},
                             {11.0 / 120, 0, 27.0 / 40, 27.0 / 40, -4.0 / 15, -4.0 / 15, 11.0 / 120},
                             {0, 1.0 / 3, 2.0 / 3, 1.0 / 3, 0.5, 0.5, 1}},
                            {}};

// Linearly implicit Euler, the step cloth simulators take since Baraff and Witkin: one
// linear solve, (I - h J) k = F(y0), y1 = y0 + h k. Backward Euler exactly for linear
// springs: stable at any step, damping every mode (the more, the larger h |lambda|).
inline constexpr Method implicit_euler{
    "implicit_euler", MethodKind::linearly_implicit, 1, {}, {}, 0, {1, 1, {}, {}, {1}, {0}}};

// ROS2 (Verwer, Spee, Blom and Hundsdorfer, 1999): second order for any J (a W-method),
// L-stable with gamma = 1 + 1/sqrt(2): stiff modes are damped out, resolved ones keep their
// energy to O(h^2). Two solves with the same matrix per step.
inline constexpr Method ros2{"ros2",
                             MethodKind::linearly_implicit,
                             2,
                             {},
                             {},
                             0,
                             {2, 1.7071067811865475, {{{}, {1}}}, {{{}, {-2}}}, {1.5, 0.5}, {0, 1}}};

// The methods with a compiled fused kernel, in a fixed order (their index is stable).
inline constexpr std::array<const Method*, 6> builtin_methods = {
    &euler, &midpoint, &heun, &rk4, &symplectic_euler, &velocity_verlet};
// Named methods without one: they take the staged path.
inline constexpr std::array<const Method*, 3> staged_methods = {&bs3, &dopri5, &rk6};
// Linearly implicit methods: particle sets, fixed steps (src/step/implicit_path.hpp).
inline constexpr std::array<const Method*, 2> implicit_methods = {&implicit_euler, &ros2};

// The built-in or staged method of that name; throws kinema::Error listing the known names.
const Method& method_by_name(std::string_view name);

// Index of `method` in builtin_methods when its coefficients equal a built-in's, else -1.
int builtin_index(const Method& method);

// Throws kinema::Error when the method is not valid (stages out of range, a not strictly
// lower triangular, non-finite coefficients, gamma not positive).
void validate(const Method& method);

}  // namespace kinema
