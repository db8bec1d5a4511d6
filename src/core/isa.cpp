// Which instruction sets this CPU runs and this build has kernels for.
#include "kinema/isa.hpp"

#include <string>

#include <xsimd/xsimd.hpp>

#include "kinema/error.hpp"

namespace kinema {
namespace {

// Whether this build has the kernels of a set (KINEMA_KERNEL_ISAS in CMake).
constexpr bool built(Isa isa) {
  switch (isa) {
#ifdef KINEMA_KERNELS_SSE2
    case Isa::sse2: return true;
#endif
#ifdef KINEMA_KERNELS_AVX2
    case Isa::avx2: return true;
#endif
#ifdef KINEMA_KERNELS_AVX512
    case Isa::avx512: return true;
#endif
    case Isa::automatic:
    case Isa::scalar: return true;
    default: return false;
  }
}

bool cpu_has(Isa isa) {
  const auto cpu = xsimd::available_architectures();
  switch (isa) {
    case Isa::sse2: return cpu.sse2;
    case Isa::avx2: return cpu.fma3_avx2;
    case Isa::avx512: return cpu.avx512f;
    default: return true;
  }
}

}  // namespace

Isa best_isa() {
  static const Isa best = [] {
    for (Isa isa : {Isa::avx512, Isa::avx2, Isa::sse2}) {
      if (isa_available(isa)) return isa;
    }
    return Isa::scalar;
  }();
  return best;
}

bool isa_available(Isa isa) {
  return built(isa) && cpu_has(isa);
}

Isa resolve_isa(Isa requested) {
  if (requested == Isa::automatic) return best_isa();
  if (!isa_available(requested)) {
    const char* why = built(requested) ? "is not supported by this CPU" : "has no kernels in this build";
    throw Error("isa " + std::string(isa_name(requested)) + " " + why + " (best: " + std::string(isa_name(best_isa())) +
                ")");
  }
  return requested;
}

std::string_view isa_name(Isa isa) {
  switch (isa) {
    case Isa::automatic: return "auto";
    case Isa::scalar: return "scalar";
    case Isa::sse2: return "sse2";
    case Isa::avx2: return "avx2";
    case Isa::avx512: return "avx512";
  }
  return "?";
}

Isa isa_by_name(std::string_view name) {
  for (Isa isa : {Isa::automatic, Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (isa_name(isa) == name) return isa;
  }
  throw Error("unknown isa '" + std::string(name) + "' (known: auto, scalar, sse2, avx2, avx512)");
}

}  // namespace kinema
