#include "step/step_paths.hpp"

namespace kinema {

template <class T>
StepPaths<T> build_paths(const ForceModel<T>& f, const Method& method, const kernels::KernelTable<T>& table,
                         bool force_staged, std::size_t staged_capacity) {
  StepPaths<T> paths;
  paths.lowered = std::make_unique<LoweredForces<T>>(lower_forces<T>(f.local_terms()));
  paths.lowered->coupled = lower_coupled<T>(f);
  const LoweredForces<T>& l = *paths.lowered;
  const int quad = l.particle.has_quadratic();
  const int builtin = builtin_index(method);
  // Rigid bodies ignore particle callbacks, as particles ignore rigid ones.
  if (builtin >= 0 && !f.coupled() && f.rigid_callbacks().empty()) {
    paths.rigid = table.rigid[builtin][l.rigid.has_quadratic()][l.rigid.has_central()];
  } else if (!f.coupled()) {
    paths.rigid_block = std::make_unique<RigidBlockPath<T>>(f, method, table, l);
  }
  if (builtin >= 0 && f.fusable() && !force_staged) {
    paths.fused = table.fused[builtin][quad][kernels::fused_variant(l.particle, false)];
    paths.fused_applied = table.fused[builtin][quad][kernels::fused_variant(l.particle, true)];
  } else if (builtin >= 0 && !f.coupled() && !force_staged) {
    paths.block = std::make_unique<BlockPath<T>>(f, method, builtin, table, l.particle);
    paths.block->reserve(staged_capacity);
  } else {
    paths.staged = std::make_unique<StagedPath<T>>(f, method, table, l.particle, l.coupled);
    paths.staged->reserve(staged_capacity);
  }
  return paths;
}

#define KINEMA_STEP_PATHS(T)                                                                                    \
  template StepPaths<T> build_paths(const ForceModel<T>&, const Method&, const kernels::KernelTable<T>&, bool,  \
                                    std::size_t);
KINEMA_STEP_PATHS(float)
KINEMA_STEP_PATHS(double)
#undef KINEMA_STEP_PATHS

}  // namespace kinema
