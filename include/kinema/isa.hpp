#pragma once
// Instruction sets the kernels are compiled for, and the run-time choice among them.

#include <string_view>

namespace kinema {

enum class Isa { automatic, scalar, sse2, avx2, avx512 };

// The best instruction set this CPU runs (never `automatic`).
Isa best_isa();
// `requested` resolved against this CPU: automatic gives best_isa(). Throws kinema::Error
// when the CPU lacks the requested set.
Isa resolve_isa(Isa requested);
bool isa_available(Isa isa);

std::string_view isa_name(Isa isa);  // "auto", "scalar", "sse2", "avx2", "avx512"
Isa isa_by_name(std::string_view name);  // throws kinema::Error on an unknown name

}  // namespace kinema
