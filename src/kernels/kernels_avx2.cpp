// The kernels for avx2, compiled with this unit's own instruction-set flags.
#define KINEMA_ISA_NS isa_avx2
#include "kernels/kernel_table.hpp"

namespace kinema::kernels {

template <>
const KernelTable<float>& avx2_table<float>() {
  static const KernelTable<float> table = isa_avx2::make_table<xsimd::batch<float, xsimd::fma3<xsimd::avx2>>>(Isa::avx2);
  return table;
}

template <>
const KernelTable<double>& avx2_table<double>() {
  static const KernelTable<double> table = isa_avx2::make_table<xsimd::batch<double, xsimd::fma3<xsimd::avx2>>>(Isa::avx2);
  return table;
}

}  // namespace kinema::kernels
