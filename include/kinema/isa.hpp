#pragma once
// Instruction sets the kernels are compiled for, and the run-time choice among them.

#include <string_view>

namespace kinema {

enum class Isa { automatic, scalar, sse2, avx2, avx512 };

// The best instruction set this CPU runs and this build has kernels for (never
// `automatic`). A build has scalar kernels always and the others that the CMake cache
// variable KINEMA_KERNEL_ISAS lists (by default all; the sanitizer presets build avx512
// alone).
Isa best_isa();
// `requested` resolved against this CPU and build: automatic gives best_isa(). Throws
// kinema::Error when the CPU lacks the requested set or the build its kernels.
Isa resolve_isa(Isa requested);
bool isa_available(Isa isa);

std::string_view isa_name(Isa isa);  // "auto", "scalar", "sse2", "avx2", "avx512"
Isa isa_by_name(std::string_view name);  // throws kinema::Error on an unknown name

}  // namespace kinema
