// The kernels for avx512, compiled with this unit's own instruction-set flags.
#define KINEMA_ISA_NS isa_avx512
#include "kernels/kernel_table.hpp"

namespace kinema::kernels {

template <>
const KernelTable<float>& avx512_table<float>() {
  static const KernelTable<float> table = isa_avx512::make_table<xsimd::batch<float, xsimd::avx512f>>(Isa::avx512);
  return table;
}

template <>
const KernelTable<double>& avx512_table<double>() {
  static const KernelTable<double> table = isa_avx512::make_table<xsimd::batch<double, xsimd::avx512f>>(Isa::avx512);
  return table;
}

}  // namespace kinema::kernels
