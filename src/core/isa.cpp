// Which instruction sets this CPU runs: xsimd::dispatch walks the list best first and stops
// at the first set this CPU supports.
#include "kinema/isa.hpp"

#include <string>

#include <xsimd/xsimd.hpp>

#include "kinema/error.hpp"

namespace kinema {
namespace {

struct BestIsa {
  Isa operator()(xsimd::avx512f) const { return Isa::avx512; }
  Isa operator()(xsimd::fma3<xsimd::avx2>) const { return Isa::avx2; }
  Isa operator()(xsimd::sse2) const { return Isa::sse2; }
};

}  // namespace

Isa best_isa() {
  static const Isa best =
      xsimd::dispatch<xsimd::arch_list<xsimd::avx512f, xsimd::fma3<xsimd::avx2>, xsimd::sse2>>(
          BestIsa{})();
  return best;
}

bool isa_available(Isa isa) {
  const auto cpu = xsimd::available_architectures();
  switch (isa) {
    case Isa::automatic:
    case Isa::scalar:
      return true;
    case Isa::sse2:
      return cpu.sse2;
    case Isa::avx2:
      return cpu.fma3_avx2;
    case Isa::avx512:
      return cpu.avx512f;
  }
  return false;
}

Isa resolve_isa(Isa requested) {
  if (requested == Isa::automatic) return best_isa();
  if (!isa_available(requested)) {
    throw Error("isa " + std::string(isa_name(requested)) + " is not supported by this CPU (best: " +
                std::string(isa_name(best_isa())) + ")");
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
