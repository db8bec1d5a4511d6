// The fuzz build's stand-in for the per-ISA kernel units. clang 14 cannot compile them (they
// take floating-point template arguments), and the fuzz targets only parse and check: they
// never step. The tables are complete; calling any kernel stops the process.
#include <cstdio>
#include <cstdlib>

#include "kernels/kernels.hpp"

namespace kinema::kernels {
namespace {

template <class Job>
void no_kernel(const Job&, std::size_t, std::size_t) {
  std::fputs("kinema fuzz build: a kernel was called, but this build has none\n", stderr);
  std::abort();
}

template <class T>
std::size_t no_event_scan(const EventScanJob<T>& job, std::size_t count, std::uint32_t*) {
  no_kernel(job, count, count);
  return 0;
}

template <class T>
KernelTable<T> make_table(Isa isa, std::size_t bytes) {
  KernelTable<T> t{};
  t.isa = isa;
  t.width = bytes == 0 ? 1 : bytes / sizeof(T);
  for (auto& m : t.fused) for (auto& q : m) for (auto& f : q) f = &no_kernel<FusedJob<T>>;
  for (auto& m : t.rigid) for (auto& q : m) for (auto& f : q) f = &no_kernel<RigidJob<T>>;
  for (auto& q : t.stage) for (auto& f : q) f = &no_kernel<StageJob<T>>;
  t.combine = &no_kernel<CombineJob<T>>;
  t.add_forces = &no_kernel<ForceJob<T>>;
  t.nbody = &no_kernel<NBodyJob<T>>;
  t.springs = &no_kernel<SpringJob<T>>;
  t.interpolate = &no_kernel<InterpolateJob<T>>;
  for (auto& f : t.event_scan) f = &no_event_scan<T>;
  return t;
}

}  // namespace

#define KINEMA_NO_KERNELS(name, isa, bytes)                                    \
  template <>                                                                  \
  const KernelTable<float>& name<float>() {                                    \
    static const KernelTable<float> table = make_table<float>(isa, bytes);     \
    return table;                                                              \
  }                                                                            \
  template <>                                                                  \
  const KernelTable<double>& name<double>() {                                  \
    static const KernelTable<double> table = make_table<double>(isa, bytes);   \
    return table;                                                              \
  }

KINEMA_NO_KERNELS(scalar_table, Isa::scalar, 0)
KINEMA_NO_KERNELS(scalar_relaxed_table, Isa::scalar, 0)
KINEMA_NO_KERNELS(sse2_table, Isa::sse2, 16)
KINEMA_NO_KERNELS(sse2_relaxed_table, Isa::sse2, 16)
KINEMA_NO_KERNELS(avx2_table, Isa::avx2, 32)
KINEMA_NO_KERNELS(avx512_table, Isa::avx512, 64)

}  // namespace kinema::kernels
