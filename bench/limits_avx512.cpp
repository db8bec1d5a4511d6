#define LIMITS_NS isa_avx512
#include "limits_impl.hpp"

namespace kinema::bench {
LimitKernels limits_avx512() { return isa_avx512::make<xsimd::avx512f>("avx512"); }
}  // namespace kinema::bench
