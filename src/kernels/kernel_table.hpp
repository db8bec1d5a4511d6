#pragma once
// Collects one instruction set's kernels into its table.

#include "kernels/block_kernels.hpp"
#include "kernels/coupled_kernels.hpp"
#include "kernels/event_kernels.hpp"
#include "kernels/kernel_impl.hpp"
#include "kernels/rigid_kernels.hpp"

namespace kinema::kernels::KINEMA_ISA_NS {

template <class V>
KernelTable<value_t<V>> make_table(Isa isa) {
  KernelTable<value_t<V>> t{};
  t.isa = isa;
  t.width = Lane<V>::width;
  static_for<int(kBuiltinCount)>([&](auto m) {
    constexpr const Method& method = *builtin_methods[m];
    static_for<kFusedVariants>([&](auto v) {
      t.fused[m][0][v] = fused_kernel<method, false, v, V>();
      t.fused[m][1][v] = fused_kernel<method, true, v, V>();
    });
    if constexpr (method.kind == MethodKind::runge_kutta) {
      t.block_advance[m][0][0] = &block_advance<method, false, false, V>;
      t.block_advance[m][0][1] = &block_advance<method, false, true, V>;
      t.block_advance[m][1][0] = &block_advance<method, true, false, V>;
      t.block_advance[m][1][1] = &block_advance<method, true, true, V>;
    }
    t.rigid[m][0][0] = rigid_kernel<method, false, false, V>();
    t.rigid[m][0][1] = rigid_kernel<method, false, true, V>();
    t.rigid[m][1][0] = rigid_kernel<method, true, false, V>();
    t.rigid[m][1][1] = rigid_kernel<method, true, true, V>();
  });
  t.stage[0][0] = &stage<false, false, V>;
  t.stage[0][1] = &stage<false, true, V>;
  t.stage[1][0] = &stage<true, false, V>;
  t.stage[1][1] = &stage<true, true, V>;
  t.end_accelerations[0][0] = &end_accelerations<false, false, V>;
  t.end_accelerations[0][1] = &end_accelerations<false, true, V>;
  t.end_accelerations[1][0] = &end_accelerations<true, false, V>;
  t.end_accelerations[1][1] = &end_accelerations<true, true, V>;
  t.combine = &combine<V>;
  t.add_forces = &add_forces<V>;
  t.nbody = &nbody<V>;
  t.springs = &springs<V>;
  t.interpolate = &interpolate<V>;
  t.block_kick[0][0] = &block_kick<false, false, V>;
  t.block_kick[0][1] = &block_kick<false, true, V>;
  t.block_kick[1][0] = &block_kick<true, false, V>;
  t.block_kick[1][1] = &block_kick<true, true, V>;
  t.block_drift = &block_drift<V>;
  t.rigid_block_stage = &rigid_block_stage<V>;
  t.rigid_block_rates[0][0] = &rigid_block_rates<false, false, V>;
  t.rigid_block_rates[0][1] = &rigid_block_rates<false, true, V>;
  t.rigid_block_rates[1][0] = &rigid_block_rates<true, false, V>;
  t.rigid_block_rates[1][1] = &rigid_block_rates<true, true, V>;
  t.rigid_block_finish = &rigid_block_finish<V>;
  t.rigid_block_turn = &rigid_block_turn<V>;
  t.event_scan[int(EventValue::plane)] = &event_scan<EventValue::plane, V>;
  t.event_scan[int(EventValue::distance)] = &event_scan<EventValue::distance, V>;
  t.event_scan[int(EventValue::speed)] = &event_scan<EventValue::speed, V>;
  t.event_scan[int(EventValue::axis_plane)] = &event_scan<EventValue::axis_plane, V>;
  t.event_scan[int(EventValue::given)] = &event_scan<EventValue::given, V>;
  return t;
}

}  // namespace kinema::kernels::KINEMA_ISA_NS
