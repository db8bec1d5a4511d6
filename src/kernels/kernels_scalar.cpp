// The kernels for scalar, compiled with this unit's own instruction-set flags.
#define KINEMA_ISA_NS isa_scalar
#include "kernels/kernel_table.hpp"

namespace kinema::kernels {

template <>
const KernelTable<float>& scalar_table<float>() {
  static const KernelTable<float> table = isa_scalar::make_table<float>(Isa::scalar);
  return table;
}

template <>
const KernelTable<double>& scalar_table<double>() {
  static const KernelTable<double> table = isa_scalar::make_table<double>(Isa::scalar);
  return table;
}

}  // namespace kinema::kernels
