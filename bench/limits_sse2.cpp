#define LIMITS_NS isa_sse2
#include "limits_impl.hpp"

namespace kinema::bench {
LimitKernels limits_sse2() { return isa_sse2::make<xsimd::sse2>("sse2"); }
}  // namespace kinema::bench
