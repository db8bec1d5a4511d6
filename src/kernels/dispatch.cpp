// The kernel table of a resolved instruction set (kinema/isa.hpp says which this CPU runs).
#include "kernels/kernels.hpp"

namespace kinema {
namespace kernels {

template <class T>
const KernelTable<T>& kernel_table(Isa isa, [[maybe_unused]] bool relaxed) {
  switch (resolve_isa(isa)) {  // only the sets this build has get past it
#ifdef KINEMA_KERNELS_AVX512
    case Isa::avx512: return avx512_table<T>();
#endif
#ifdef KINEMA_KERNELS_AVX2
    case Isa::avx2: return avx2_table<T>();
#endif
#ifdef KINEMA_KERNELS_SSE2
    case Isa::sse2:
#ifdef KINEMA_KERNELS_RELAXED
      if (relaxed) return sse2_relaxed_table<T>();
#endif
      return sse2_table<T>();
#endif
    default:
#ifdef KINEMA_KERNELS_RELAXED
      if (relaxed) return scalar_relaxed_table<T>();
#endif
      return scalar_table<T>();
  }
}

template const KernelTable<float>& kernel_table<float>(Isa, bool);
template const KernelTable<double>& kernel_table<double>(Isa, bool);

}  // namespace kernels
}  // namespace kinema
