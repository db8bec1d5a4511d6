#pragma once
// The kernels' interface: plain data in, function pointers out. One table per instruction
// set and value type; the stepper picks a table once and calls through it per block.

#include <array>
#include <cstddef>
#include <cstdint>

#include "kinema/isa.hpp"
#include "kinema/methods.hpp"

namespace kinema::kernels {

// The local force terms of a model, summed and converted to T once per stepper.
template <class T>
struct LocalForces {
  std::array<T, 3> gravity{};
  T spring_k = 0;               // sum of spring constants
  std::array<T, 3> anchor{};    // their k-weighted mean anchor
  T linear = 0;                 // linear drag k plus spring damping
  T quadratic = 0;              // quadratic drag k
  int central_count = 0;
  std::array<std::array<T, 3>, 4> center{};
  std::array<T, 4> mu{};
  std::array<T, 3> constant_force{};  // sum of point forces (rigid bodies only)
  bool has_quadratic() const { return quadratic != 0; }
  bool has_central() const { return central_count > 0; }
};

// What single bodies carry besides their state, each nullptr when the set has none: forces
// applied to them (ParticleSet::apply_force; constant over the call), gravity factors and
// linear damping rates (BodyParameters). The plain fused particle kernels read none of them.
template <class T>
struct PerBody {
  const T* applied[3];
  const T* gravity_factor;
  const T* linear_damping;
  bool any() const { return applied[0] != nullptr || gravity_factor != nullptr || linear_damping != nullptr; }
  // The same arrays from body `begin` on.
  PerBody from(std::size_t begin) const {
    auto at = [&](const T* p) { return p != nullptr ? p + begin : nullptr; };
    return {{at(applied[0]), at(applied[1]), at(applied[2])}, at(gravity_factor), at(linear_damping)};
  }
};

template <class T>
struct BodyArrays {
  T* x[3];         // px py pz
  T* v[3];         // vx vy vz
  const T* inv_mass;
  PerBody<T> per_body;
};

// The rotational terms of a model, for rigid bodies.
template <class T>
struct RotationalForces {
  std::array<T, 3> torque{};
  T angular_drag = 0;
  int point_count = 0;
  std::array<std::array<T, 3>, 4> point{};  // body frame
  std::array<std::array<T, 3>, 4> force{};  // world frame
};

// One fused rigid-body step over bodies [begin, end).
template <class T>
struct RigidJob {
  BodyArrays<T> bodies;  // centres of mass
  T* q[4];
  T* l[3];
  const T* inv_inertia[3];
  LocalForces<T> forces;
  RotationalForces<T> rotation;
  T h;
  bool renormalize;
  const T* torque[3];  // applied per body (world frame); nullptr when none
  const T* angular_damping;  // per body (BodyParameters); nullptr when none
};
template <class T>
using RigidFn = void (*)(const RigidJob<T>& job, std::size_t begin, std::size_t end);

// The rigid block path (rigid callbacks, user tableaus): one phase of a step over bodies
// [begin, end) of one block, the stage state in memory where callbacks read it. Weights are
// run-time: y_s = y0 + sum_j w_j k_j over the nonzero terms in j order, one fma per term
// (w_j = h a_sj, or h b_j).
template <class T>
struct RigidBlockJob {
  T* x[3];  // the bodies' state, updated by finish, kicks and turns
  T* v[3];
  T* q[4];
  T* l[3];
  const T* inv_mass;
  const T* inv_inertia[3];
  PerBody<T> per_body;
  const T* applied_torque[3];  // nullptr when none
  const T* angular_damping;    // nullptr when none
  // The stage state a callback sees, and what it adds.
  T* xs[3];
  T* vs[3];  // also the stage's position rate
  T* qs[4];
  T* ls[3];
  T* omega[3];
  T* force[3];
  T* torque[3];
  // The rates of earlier stages (stage: j < terms; finish: all) and of this one (rates).
  const T* kx[kMaxStages][3];
  T* kv[kMaxStages][3];
  T* kq[kMaxStages][4];
  T* kl[kMaxStages][3];
  int terms = 0;  // nonzero terms: the stages term[0 .. terms) with weight[0 .. terms)
  std::array<int, kMaxStages> term{};
  std::array<T, kMaxStages> weight{};
  int stage = 0;  // rates: the stage whose rates are written
  LocalForces<T> forces;
  RotationalForces<T> rotation;
  bool renormalize = true;
  T turn_step = 0;     // turn: w h of the drift
  int turn_order = 1;  // turn: 1 Euler, 2 midpoint
};
template <class T>
using RigidBlockFn = void (*)(const RigidBlockJob<T>& job, std::size_t begin, std::size_t end);

// The block paths step a block in slices of this many bodies (a multiple of the widest SIMD
// width; callbacks see one slice): 128 floats or 64 doubles, the fastest of 64, 128 and 256
// floats on the bench scenes.
template <class T>
inline constexpr std::size_t kSliceBodies = 512 / sizeof(T);

// The particle block path (callbacks with a built-in method): the phases of a step over one
// slice of bodies, the stage state in the slice's scratch where callbacks read it (kept in
// the L1 cache while the slice takes its steps), the method's weights compile-time constants
// as in the fused kernels. Stage 0's state is the bodies' own.
template <class T>
struct BlockJob {
  BodyArrays<T> bodies;  // updated by the last stage, kicks and drifts
  LocalForces<T> forces;
  T h;
  T accel_scale;  // sigma h (see acceleration_scale); 1 for kicks
};
// Where each array of a slice's scratch starts, in arrays of kSliceBodies elements: stage
// positions and velocities (the position rates; stages 1 and on), stage accelerations times
// accel_scale, and what callbacks add. A kick-drift method counts as one stage.
struct SliceLayout {
  int stages;
  constexpr std::size_t xs(int s, int d) const { return std::size_t((s - 1) * 3 + d); }
  constexpr std::size_t vs(int s, int d) const { return std::size_t((stages + s - 2) * 3 + d); }
  constexpr std::size_t kv(int s, int d) const { return std::size_t((2 * stages + s - 2) * 3 + d); }
  constexpr std::size_t force(int d) const { return std::size_t((3 * stages - 2) * 3 + d); }
  constexpr std::size_t arrays() const { return std::size_t((3 * stages - 1) * 3); }
};
// A stage's rates and the next stage's state (or the step's end) over `count` bodies from
// `begin`, the slice's stage state in `scratch`.
template <class T>
using BlockStageFn = void (*)(const BlockJob<T>& job, T* scratch, int stage, std::size_t begin, std::size_t count);
template <class T>
using BlockStepFn = void (*)(const BlockJob<T>& job, T* scratch, T step, std::size_t begin, std::size_t count);

// One fused step over bodies [begin, end) (multiples of the SIMD width).
template <class T>
struct EventProbe;

template <class T>
struct FusedJob {
  BodyArrays<T> bodies;
  LocalForces<T> forces;
  T h;
  // Where the particle kernels read px .. vz (six arrays) when that is not where they write
  // them: the finiteness guard steps the set's state into a second buffer in the same pass.
  // Null: in place.
  const T* const* source = nullptr;
  // Where the kernel also writes each body's px .. vz as the step found them (six arrays, the
  // events' test reads both ends of the step from there and the set). Null: nowhere.
  T* const* before = nullptr;
  // With `before`: the events' sign test, run on both ends of each batch's step in registers;
  // only the batches where a body may have crossed store their start state, packed: the k-th
  // batch listed (EventProbe::batches) at k * width from `before`. Null: every batch stores
  // it at its own place.
  EventProbe<T>* probe = nullptr;
};
template <class T>
using FusedFn = void (*)(const FusedJob<T>& job, std::size_t begin, std::size_t end);

// Runge-Kutta stages carry their accelerations pre-multiplied by sigma h, sigma being the
// tableau's first nonzero a_sj (1/2 for rk4 and midpoint; see below): a stage velocity v + h a_sj k_j
// then takes (a_sj / sigma) K_j, an add where that is 1, and the FMA pipes, which bound the
// fused kernels, do less work. The scaling goes into the force coefficients, once per call:
// no per-body cost.
// sigma is used only when it is a power of two from 1/64 to 64, so scaling by it is exact
// and a user tableau's other weights divided by it stay finite; else it is 1.
constexpr double acceleration_scale(const ButcherTableau& t) {
  for (int s = 0; s < t.stages; ++s) {
    for (int j = 0; j < s; ++j) {
      if (t.a[s][j] == 0) continue;
      for (double p = 1.0 / 64; p <= 64; p *= 2) {
        if (t.a[s][j] == p) return p;
      }
      return 1;
    }
  }
  return 1;
}

// A weighted sum sum_j w_j k_j is formed as w_f (G_0 + r_1 G_1 + r_2 G_2 + ...): w_f is the
// first nonzero weight, the terms are grouped by their ratio w_j / w_f (groups in order of
// first appearance, G_g the sum of its terms in j order, r_0 = 1). RK4's final
// k0 + 2 k1 + 2 k2 + k3 becomes (k0 + k3) + 2 (k1 + k2): one operation fewer per component.
struct TermGroups {
  int count = 0;
  std::array<double, kMaxStages> ratio{};  // per group
  std::array<int, kMaxStages> lead{};      // each group's first term
  std::array<int, kMaxStages> group{};     // per term; -1 for a zero weight

  constexpr void add(int term, double w, double first_w) {
    const double r = w / first_w;
    int g = 0;
    while (g < count && ratio[g] != r) ++g;
    if (g == count) ratio[count] = r, lead[count++] = term;
    group[term] = g;
  }
};

// One tableau row (a row of A, or b) as both paths evaluate it: the fused kernels at
// compile time, the staged path at run time. Their bits agree because both take the
// grouping and the steps from here.
struct RowSum {
  TermGroups groups;
  double first = 0;  // w_f; 0 for a row of zeros

  constexpr bool empty() const { return groups.count == 0; }
  // The factor of the grouped sum for positions: x + (w_f h) (G_0 + ...).
  template <class T>
  constexpr T position_step(T h) const {
    return T(first) * h;
  }
  // For velocities, whose k are accelerations already scaled by sigma h (see
  // acceleration_scale): v + (w_f / sigma) (G_0 + ...).
  template <class T>
  constexpr T velocity_step(double sigma) const {
    return T(first / sigma);
  }
};

constexpr RowSum row_sum(const std::array<double, kMaxStages>& w) {
  RowSum row;
  for (int j = 0; j < kMaxStages; ++j) {
    row.groups.group[j] = -1;
    if (w[j] == 0) continue;
    if (row.first == 0) row.first = w[j];
    row.groups.add(j, w[j], row.first);
  }
  return row;
}

// out = in + step * (G_0 + r_1 G_1 + ...) for the three components of a vector field, the
// terms k[j] those of a RowSum (step: see RowSum).
template <class T>
struct Combination {
  const T* in[3];
  T* out[3];
  int terms = 0;  // k[0 .. terms) are set where the row's weight is nonzero
  T step = 0;
  TermGroups groups;
  std::array<T, kMaxStages> ratio{};  // groups.ratio in T
  const T* k[kMaxStages][3];

  bool empty() const { return groups.count == 0; }
  // Takes the first `count` terms of `row`; field(j) gives term j's three arrays.
  template <class Field>
  void set(const RowSum& row, int count, Field&& field) {
    groups = row.groups;
    terms = count;
    for (int g = 0; g < groups.count; ++g) ratio[g] = T(groups.ratio[g]);
    for (int j = 0; j < count; ++j) {
      if (groups.group[j] < 0) continue;
      const std::array<const T*, 3> arrays = field(j);
      for (int d = 0; d < 3; ++d) k[j][d] = arrays[d];
    }
  }
};

// One stage of the staged path: stage state (x_s, v_s) = (x, v) + the combinations (when
// there are terms), then acc = accel_scale * local accelerations at (x_s, v_s).
template <class T>
struct StageJob {
  Combination<T> x, v;
  T accel_scale;
  const T* inv_mass;
  PerBody<T> per_body;
  T* acc[3];
  LocalForces<T> forces;
};
template <class T>
using StageFn = void (*)(const StageJob<T>& job, std::size_t begin, std::size_t end);

// The local accelerations of one SIMD group at both ends of a step (an event's crossing):
// acc[e] at (x[e], v[e]), e = 0 the start, 1 the end, every array from the group's first body.
// The same operations as StageJob's at accel_scale 1 with no combinations, so the same bits.
template <class T>
struct EndsJob {
  const LocalForces<T>* forces;
  const T* x[2][3];
  const T* v[2][3];
  const T* inv_mass;
  PerBody<T> per_body;
  T* acc[2][3];
};
template <class T>
using EndsFn = void (*)(const EndsJob<T>& job);

template <class T>
struct CombineJob {
  Combination<T> c;
};
template <class T>
using CombineFn = void (*)(const CombineJob<T>& job, std::size_t begin, std::size_t end);

// acc += inv_mass * (scale * force) for bodies with inv_mass != 0.
template <class T>
struct ForceJob {
  T* acc[3];
  const T* force[3];
  const T* inv_mass;
  T scale;
};
template <class T>
using AddForcesFn = void (*)(const ForceJob<T>& job, std::size_t begin, std::size_t end);

// N-body gravity on the targets [begin, end) from every source: acc += scale_G * sum_j
// m_j r_ij / (|r_ij|^2 + eps2)^(3/2) for targets with inv_mass != 0, each target's sum over
// j in index order. Sources with inv_mass 0 have no mass.
template <class T>
struct NBodyJob {
  const T* x[3];        // all bodies' positions at the stage
  const T* inv_mass;
  std::size_t sources;  // the padded body count
  T eps2;               // softening squared
  T scale_G;            // stage acceleration scale times G
  T* acc[3];
  bool fast;            // float: the fast inverse cube (coupled_kernels.hpp), not exact
};
template <class T>
using NBodyFn = void (*)(const NBodyJob<T>& job, std::size_t begin, std::size_t end);
// Targets per call, at most (the kernel sums them on its stack): the stepper's block.
inline constexpr std::size_t kMaxNBodyTargets = 1024;

// A spring network in sliced ELLPACK form: bodies in slices of kSpringSlice, each slice a
// run of entries, one per spring slot, kSpringSlice lanes each (lane l for body slice *
// kSpringSlice + l). Empty slots point at the body itself, with zero parameters and a
// rest length of -1. Calls start on a slice boundary.
inline constexpr std::size_t kSpringSlice = 16;
template <class T>
struct SpringJob {
  const T* x[3];
  const T* v[3];
  std::size_t covered;                 // bodies the network reaches (max index + 1)
  const std::uint32_t* slice_offset;   // slices + 1: the first entry of each slice
  const std::int32_t* neighbor;        // [entry][lane]
  // Per entry: first >= 0 when lane l's other end is first + l for every lane; -1 when
  // gathered; -(first + 2) when that holds for the lanes that have a spring and the others
  // (rest < 0) must be masked.
  const std::int32_t* contiguous;
  const T* rest;                       // [entry][lane], likewise k and damping
  const T* k;
  const T* damping;
  T* force[3];                         // forces are added here
};
template <class T>
using SpringFn = void (*)(const SpringJob<T>& job, std::size_t begin, std::size_t end);

// Drawing between two steps: out = previous + alpha (current - previous) for positions, and
// for orientations (q arrays set) the normalized lerp toward current or -current, whichever
// is nearer (the short arc).
template <class T>
struct InterpolateJob {
  const T* previous[3];
  const T* current[3];
  T* out[3];
  const T* previous_q[4];  // null for particles
  const T* current_q[4];
  T* out_q[4];
  T alpha;
};
template <class T>
using InterpolateFn = void (*)(const InterpolateJob<T>& job, std::size_t begin, std::size_t end);

inline constexpr std::size_t kBuiltinCount = builtin_methods.size();

// The fused particle kernels come in three variants, so that a model pays only for what it
// uses: plain; with central attractors (their count known at run time), which also reads
// applied forces where the set has them; with applied forces. Variants give the same bits
// wherever more than one applies. The rigid kernels take [central] only: the Runge-Kutta ones
// choose per call whether to read applied forces and torques, the kick-drift ones and the
// stage kernel test for them per batch.
inline constexpr int kPlainVariant = 0, kCentralVariant = 1, kAppliedVariant = 2, kFusedVariants = 3;
template <class T>
constexpr int fused_variant(const LocalForces<T>& f, bool applied) {
  return f.has_central() ? kCentralVariant : applied ? kAppliedVariant : kPlainVariant;
}

// Events (kinema/events.hpp): which bodies' event values changed sign over one step.
enum class EventValue { plane, distance, speed, axis_plane, given };
inline constexpr int kEventValues = 5;
template <class T>
struct EventScanJob {
  const T* before[6];  // px .. vz at the step's start, from the first body scanned
  const T* after[6];   // and at its end
  // plane: a . x - b; distance: |x - a|^2 - b (b the radius squared); speed: |v|^2 - b;
  // axis_plane (a plane whose normal is along an axis): a[axis] x[axis] - b, one array read;
  // given: the values themselves, in before[0] and after[0] (a user's event function's)
  EventValue value = EventValue::plane;
  T a[3];
  T b;
  int axis = 0;
  bool down, up;  // the sign changes that count: > 0 to <= 0, < 0 to >= 0
  // axis_plane: outside [band[0], band[1]] the value of x[axis], rounded, has a strict sign
  // (sign(a[axis]) above the band, the other below; banded, not where the band overflows T):
  // the fused kernels' probe compares both ends of a body's step with it, with no products.
  bool banded = false;
  T band[2] = {0, 0};
};
// The sign tests a fused kernel runs as it steps (FusedJob::probe): at most kProbeTests
// built-in events. Each batch with a body that may have crossed any of them is listed by its
// first body's index, in order; the caller then tests that batch's bodies one by one.
inline constexpr int kProbeTests = 4;
template <class T>
struct EventProbe {
  const EventScanJob<T>* tests = nullptr;  // their values and directions (not their arrays)
  int count = 0;
  std::uint32_t* batches = nullptr;  // room for one entry per batch stepped
  std::size_t found = 0;
};
// Writes the indices (from 0) of the bodies among `count` (a multiple of the width) whose
// value crossed into `found`, in order; returns how many.
template <class T>
using EventScanFn = std::size_t (*)(const EventScanJob<T>& job, std::size_t count, std::uint32_t* found);

template <class T>
struct KernelTable {
  Isa isa;
  std::size_t width;  // SIMD lanes
  // [builtin method index][quadratic drag][variant, or central terms]
  FusedFn<T> fused[kBuiltinCount][2][kFusedVariants];
  RigidFn<T> rigid[kBuiltinCount][2][2];
  StageFn<T> stage[2][2];
  EndsFn<T> end_accelerations[2][2];  // [quadratic drag][central terms]
  CombineFn<T> combine;
  AddForcesFn<T> add_forces;
  NBodyFn<T> nbody;
  SpringFn<T> springs;
  InterpolateFn<T> interpolate;
  // The particle block path, Runge-Kutta methods: a stage's rates and the next stage's state
  // or the step's end [quadratic][central] (null where a method is kick-drift); kick-drift
  // methods: a kick [quadratic][central] and a drift.
  BlockStageFn<T> block_advance[kBuiltinCount][2][2];
  BlockStepFn<T> block_kick[2][2];
  BlockStepFn<T> block_drift;
  // The rigid block path: stage state and the callbacks' view; the stage's rates
  // [quadratic drag][central terms]; the final combination; a drift's turn of q.
  RigidBlockFn<T> rigid_block_stage;
  RigidBlockFn<T> rigid_block_rates[2][2];
  RigidBlockFn<T> rigid_block_finish;
  RigidBlockFn<T> rigid_block_turn;
  EventScanFn<T> event_scan[kEventValues];  // [EventValue]
};

// The table of an available instruction set (`isa` resolved, not automatic). `relaxed`
// picks the multiply-then-add build of the scalar and SSE2 paths (others have FMA units).
template <class T>
const KernelTable<T>& kernel_table(Isa isa, bool relaxed = false);

// Defined each in its own translation unit, compiled with that unit's flags.
template <class T> const KernelTable<T>& scalar_table();
template <class T> const KernelTable<T>& sse2_table();
template <class T> const KernelTable<T>& avx2_table();
template <class T> const KernelTable<T>& avx512_table();
template <class T> const KernelTable<T>& scalar_relaxed_table();
template <class T> const KernelTable<T>& sse2_relaxed_table();

}  // namespace kinema::kernels
