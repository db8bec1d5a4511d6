// The kernels for sse2, compiled with this unit's own instruction-set flags.
#define KINEMA_ISA_NS isa_sse2
#include "kernels/kernel_table.hpp"

namespace kinema::kernels {

template <>
const KernelTable<float>& sse2_table<float>() {
  static const KernelTable<float> table = isa_sse2::make_table<xsimd::batch<float, xsimd::sse2>>(Isa::sse2);
  return table;
}

template <>
const KernelTable<double>& sse2_table<double>() {
  static const KernelTable<double> table = isa_sse2::make_table<xsimd::batch<double, xsimd::sse2>>(Isa::sse2);
  return table;
}

}  // namespace kinema::kernels
