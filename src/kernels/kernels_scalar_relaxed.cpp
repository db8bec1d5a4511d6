// The kernels for scalar with multiply-then-add instead of fused multiply-add (opt-in).
#define KINEMA_ISA_NS isa_scalar_relaxed
#define KINEMA_RELAXED_FMA 1
#include "kernels/kernel_table.hpp"

namespace kinema::kernels {

template <>
const KernelTable<float>& scalar_relaxed_table<float>() {
  static const KernelTable<float> table = isa_scalar_relaxed::make_table<float>(Isa::scalar);
  return table;
}

template <>
const KernelTable<double>& scalar_relaxed_table<double>() {
  static const KernelTable<double> table = isa_scalar_relaxed::make_table<double>(Isa::scalar);
  return table;
}

}  // namespace kinema::kernels
