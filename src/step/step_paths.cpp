#include "step/step_paths.hpp"

#include <algorithm>
#include <variant>

namespace kinema {

template <class T>
std::size_t StepPaths<T>::particle_capacity() const {
  return staged ? staged->capacity() : block ? block->capacity() : implicit ? implicit->capacity() : 0;
}

// A point spring's force turns with the body: the fused rigid kernels, which step the centre
// and the rotation apart, do not take it.
template <class T>
bool has_point_springs(const ForceModel<T>& f) {
  const auto is_point_spring = [](const LocalTerm& t) { return std::holds_alternative<PointSpring>(t); };
  return std::any_of(f.local_terms().begin(), f.local_terms().end(), is_point_spring);
}

template <class T>
bool centres_move_alone(const ForceModel<T>& f) {
  return !f.couples_rigid() && f.rigid_callbacks().empty() && !has_point_springs(f);
}

template <class T>
StepPaths<T> build_paths(const ForceModel<T>& f, const Method& method, const kernels::KernelTable<T>& table,
                         const StepperOptions& options, PathCapacity capacity) {
  StepPaths<T> paths;
  paths.lowered = std::make_unique<LoweredForces<T>>(lower_forces<T>(f.local_terms()));
  paths.lowered->coupled = lower_coupled<T>(f);
  const LoweredForces<T>& l = *paths.lowered;
  if (method.kind == MethodKind::linearly_implicit) {  // particles only: rigid sets are refused
    paths.implicit = std::make_unique<ImplicitPath<T>>(f, method, table, l, options);
    paths.implicit->reserve(capacity.particles);
    return paths;
  }
  const bool force_staged = options.force_staged;
  const int quad = l.particle.has_quadratic();
  const int builtin = builtin_index(method);
  // Rigid bodies ignore particle callbacks, as particles ignore rigid ones (and point springs
  // and body springs).
  const bool rigid_fused = builtin >= 0 && method.embedded_order == 0 && centres_move_alone(f);
  if (rigid_fused) {
    paths.rigid = table.rigid[builtin][l.rigid.has_quadratic()][l.rigid.has_central()];
  } else {
    paths.rigid_block = std::make_unique<RigidBlockPath<T>>(f, method, table, l);
    paths.rigid_block->reserve(capacity.rigid);
  }
  if (builtin >= 0 && f.fusable() && !force_staged) {
    paths.fused = table.fused[builtin][quad][kernels::fused_variant(l.particle, false)];
    paths.fused_applied = table.fused[builtin][quad][kernels::fused_variant(l.particle, true)];
  } else if (builtin >= 0 && !f.coupled() && !force_staged) {
    paths.block = std::make_unique<BlockPath<T>>(f, method, builtin, table, l.particle);
    paths.block->reserve(capacity.particles);
  } else {
    paths.staged = std::make_unique<StagedPath<T>>(f, method, table, l.particle, l.coupled);
    paths.staged->reserve(capacity.particles);
  }
  return paths;
}

#define KINEMA_STEP_PATHS(T)                                                                                    \
  template struct StepPaths<T>;                                                                                \
  template StepPaths<T> build_paths(const ForceModel<T>&, const Method&, const kernels::KernelTable<T>&,        \
                                    const StepperOptions&, PathCapacity);                                      \
  template bool centres_move_alone(const ForceModel<T>&);
KINEMA_STEP_PATHS(float)
KINEMA_STEP_PATHS(double)
#undef KINEMA_STEP_PATHS

}  // namespace kinema
