// The kernels for sse2 with multiply-then-add instead of fused multiply-add (opt-in).
#define KINEMA_ISA_NS isa_sse2_relaxed
#define KINEMA_RELAXED_FMA 1
#include "kernels/kernel_table.hpp"

namespace kinema::kernels {

template <>
const KernelTable<float>& sse2_relaxed_table<float>() {
  static const KernelTable<float> table = isa_sse2_relaxed::make_table<xsimd::batch<float, xsimd::sse2>>(Isa::sse2);
  return table;
}

template <>
const KernelTable<double>& sse2_relaxed_table<double>() {
  static const KernelTable<double> table = isa_sse2_relaxed::make_table<xsimd::batch<double, xsimd::sse2>>(Isa::sse2);
  return table;
}

}  // namespace kinema::kernels
