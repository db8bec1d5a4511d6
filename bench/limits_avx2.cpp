#define LIMITS_NS isa_avx2
#include "limits_impl.hpp"

namespace kinema::bench {
LimitKernels limits_avx2() { return isa_avx2::make<xsimd::fma3<xsimd::avx2>>("avx2"); }
}  // namespace kinema::bench
