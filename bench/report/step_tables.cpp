// Tables of whole steps beside the particle kernel: rigid bodies, an engine's frame, the
// finiteness guard and the error-controlled driver.
#include <cstdio>

#include "machine_limits.hpp"
#include "names.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

void print_rigid_row(const Results& results, const std::string& p, int threads) {
  const std::string run = rigid_run("rigid", p, results.isa(), threads);
  const auto rigid = results.find(run, "ns_per_body_step");
  if (!rigid) return;
  const auto ceiling = results.find(rigid_run("rigid-ceiling", p, results.isa(), threads), "ns_per_body_step");
  const auto particle = results.find(kernel_run("fused", "rk4", p, results.isa(), threads, 100000), "ns_per_body_step");
  const auto flops = results.find(run, "GFLOP_per_s");
  std::printf("%-6s N = 100000, %d thread%s: %.3f (%s a particle step; ceiling %s; %s of the FMA peak)\n",
              p.c_str(), threads, threads > 1 ? "s" : "", rigid->median, cell(ratio(rigid, particle), "%.1fx").c_str(),
              cell(percent(ratio(ceiling, rigid)), "%.0f%%").c_str(),
              cell(percent(ratio(flops, fma_peak(results, p, threads))), "%.0f%%").c_str());
}

void print_guard_row(const Results& results, Noise& noise, const std::string& p, long n) {
  const std::string at = "/" + results.isa() + "/" + std::to_string(n) + "/real_time";
  const auto off = results.find("guard/" + p + "/off" + at, "ns_per_body_step");
  if (!off) return;
  const auto check = results.find("guard/" + p + "/check" + at, "ns_per_body_step");
  const auto clamp = results.find("guard/" + p + "/clamp" + at, "ns_per_body_step");
  // Bytes per body the guard moves (12 arrays read, 6 written) over bytes per ns.
  const auto s = state_stream(results, p, n, 1);
  const double pass_ns = s ? 18.0 * value_bytes(p) / s->median : 0;
  for (const auto& r : {off, check, clamp}) {
    if (r) noise.add(r->cv);
  }
  std::printf("%-6s %8ld | off %.3f | check %s (%s) | clamp %s (%s) | guard traffic %s\n", p.c_str(), n,
              off->median, cell(median(check), "%.3f").c_str(), cell(ratio(check, off), "%.2fx").c_str(),
              cell(median(clamp), "%.3f").c_str(), cell(ratio(clamp, off), "%.2fx").c_str(),
              pass_ns > 0 ? cell(pass_ns, "%.3f").c_str() : "-");
}

void print_events_row(const Results& results, Noise& noise, const std::string& p) {
  const std::string at = "/" + results.isa() + "/100000/real_time";
  const auto off = results.find("events/" + p + "/off" + at, "ns_per_body_step");
  if (!off) return;
  const auto floor = results.find("events/" + p + "/floor" + at, "ns_per_body_step");
  const auto four = results.find("events/" + p + "/four" + at, "ns_per_body_step");
  const auto far = results.find("events/" + p + "/far-plane" + at, "ns_per_body_step");
  for (const auto& r : {off, floor, four, far}) {
    if (r) noise.add(r->cv);
  }
  // The step's own traffic (7 arrays read, 6 written) at this size's state-stream speed.
  const auto s = state_stream(results, p, 100000, 1);
  const double step_ns = s ? 13.0 * value_bytes(p) / s->median : 0;
  const auto staged_off = results.find("events/" + p + "/dopri5-off" + at, "ns_per_body_step");
  const auto staged_floor = results.find("events/" + p + "/dopri5-floor" + at, "ns_per_body_step");
  const auto adaptive_off = results.find("events/" + p + "/adaptive-off" + at, "ns_per_body_step");
  const auto adaptive_floor = results.find("events/" + p + "/adaptive-floor" + at, "ns_per_body_step");
  for (const auto& r : {staged_off, staged_floor, adaptive_off, adaptive_floor}) {
    if (r) noise.add(r->cv);
  }
  std::printf("%-6s off %.3f | floor %s (%s) | four %s (%s) | %s hits per step | no crossing %s (%s)"
              " | the step's traffic %s | dopri5 (staged) off %s, floor %s (%s) | advance_to off %s, floor %s (%s)\n",
              p.c_str(), off->median, cell(median(floor), "%.3f").c_str(), cell(ratio(floor, off), "%.2fx").c_str(),
              cell(median(four), "%.3f").c_str(), cell(ratio(four, off), "%.2fx").c_str(),
              results.value("events/" + p + "/floor" + at, "hits_per_step", "%.0f").c_str(),
              cell(median(far), "%.3f").c_str(), cell(ratio(far, off), "%.2fx").c_str(),
              step_ns > 0 ? cell(step_ns, "%.3f").c_str() : "-", cell(median(staged_off), "%.3f").c_str(),
              cell(median(staged_floor), "%.3f").c_str(), cell(ratio(staged_floor, staged_off), "%.2fx").c_str(),
              cell(median(adaptive_off), "%.3f").c_str(), cell(median(adaptive_floor), "%.3f").c_str(),
              cell(ratio(adaptive_floor, adaptive_off), "%.2fx").c_str());
}

// Rigid bodies on the fused rigid kernel: off and floor, and the step's own traffic (17
// arrays read, 13 written).
void print_rigid_events_row(const Results& results, Noise& noise, const std::string& p) {
  const std::string at = "/" + results.isa() + "/100000/real_time";
  const auto off = results.find("events/rigid-" + p + "/off" + at, "ns_per_body_step");
  if (!off) return;
  const auto floor = results.find("events/rigid-" + p + "/floor" + at, "ns_per_body_step");
  noise.add(off->cv);
  if (floor) noise.add(floor->cv);
  const auto s = state_stream(results, p, 100000, 1);
  const double step_ns = s ? 30.0 * value_bytes(p) / s->median : 0;
  std::printf("rigid %-6s off %.3f | floor %s (%s) | %s hits per step | the step's traffic %s\n", p.c_str(),
              off->median, cell(median(floor), "%.3f").c_str(), cell(ratio(floor, off), "%.2fx").c_str(),
              results.value("events/rigid-" + p + "/floor" + at, "hits_per_step", "%.0f").c_str(),
              step_ns > 0 ? cell(step_ns, "%.3f").c_str() : "-");
}

void print_adaptive_row(const Results& results, Noise& noise, const std::string& p) {
  const std::string at = "/" + results.isa() + "/100000/real_time";
  const auto adaptive = results.find("adaptive/dopri5/" + p + at, "ns_per_body_step");
  if (!adaptive) return;
  const auto fixed = results.find("fixed/dopri5/" + p + at, "ns_per_body_step");
  noise.add(adaptive->cv);
  const auto bw = ratio(results.find("adaptive/dopri5/" + p + at, "GB_per_s"), state_stream(results, p, 100000, 1));
  std::printf("%-6s adaptive %.3f (%s steps per call) | fixed %s | adaptive / fixed %s | %s of the stream\n",
              p.c_str(), adaptive->median, results.value("adaptive/dopri5/" + p + at, "accepted_per_call", "%.0f").c_str(),
              cell(median(fixed), "%.3f").c_str(), cell(ratio(adaptive, fixed), "%.2fx").c_str(),
              cell(percent(bw), "%.1f%%").c_str());
}

bool has_rigid(const Results& results) {
  for (const std::string p : {"float", "double"}) {
    for (int threads : {1, 2}) {
      if (results.find(rigid_run("rigid", p, results.isa(), threads), "ns_per_body_step")) return true;
    }
  }
  return false;
}

}  // namespace

void print_rigid_table(const Results& results) {
  if (!has_rigid(results)) return;
  std::printf("\nRigid bodies, RK4, %s: ns per body-step (cost relative to a particle); the kernel's 597 flops "
              "per body-step (FMA = 2) as a share of the FMA peak at that thread count\n", results.isa().c_str());
  for (const std::string p : {"float", "double"}) {
    for (int threads : {1, 2}) print_rigid_row(results, p, threads);
  }
}

void print_frame_table(const Results& results, Noise& noise) {
  if (!results.find("frame/copy/float/100000/real_time", "ns_per_body_step")) return;
  std::printf("\nA frame at N = 100000, 1 thread, %s (previous = current, one rk4 step, interpolate): "
              "ns per body-frame (times a plain copy of the set)\n", results.isa().c_str());
  for (const std::string p : {"float", "double"}) {
    const auto frame = results.find("frame/" + p + "/" + results.isa() + "/100000/real_time", "ns_per_body_step");
    const auto copy = results.find("frame/copy/" + p + "/100000/real_time", "ns_per_body_step");
    if (!frame) continue;
    noise.add(frame->cv);
    std::printf("%-6s %.3f (%s; the copy alone %s)\n", p.c_str(), frame->median,
                cell(ratio(frame, copy), "%.1fx").c_str(), cell(median(copy), "%.3f").c_str());
  }
}

void print_guard_table(const Results& results, Noise& noise) {
  if (!results.find("guard/float/off/" + results.isa() + "/100000/real_time", "ns_per_body_step")) return;
  std::printf("\nThe finiteness guard, one rk4 step per call, 1 thread, %s: ns per body-step (times the "
              "guard off); the guard's own traffic (a copy of 6 arrays, a scan of 6) at this size's state-stream speed\n",
              results.isa().c_str());
  for (const std::string p : {"float", "double"}) {
    for (long n : {100000L, 1L << 20}) print_guard_row(results, noise, p, n);
  }
}

void print_events_table(const Results& results, Noise& noise) {
  if (!results.find("events/float/off/" + results.isa() + "/100000/real_time", "ns_per_body_step")) return;
  std::printf("\nEvents, 100k bodies falling onto a plane, one rk4 step per call, 1 thread, %s: ns per body-step "
              "(times no events); floor: one plane event, four: plane, distance, speed and a user function; "
              "no crossing: a plane no body reaches (the kernel's test alone, nothing to locate); "
              "dopri5 takes the staged path; advance_to: a frame's error-controlled dopri5 steps "
              "(rtol = atol = 1e-6), per step accepted; rigid: turning bodies on the fused rigid kernel\n",
              results.isa().c_str());
  for (const std::string p : {"float", "double"}) print_events_row(results, noise, p);
  for (const std::string p : {"float", "double"}) print_rigid_events_row(results, noise, p);
}

void print_adaptive_table(const Results& results, Noise& noise) {
  if (!results.find("adaptive/dopri5/float/" + results.isa() + "/100000/real_time", "ns_per_body_step")) return;
  std::printf("\nError-controlled dopri5 against fixed steps at its mean accepted step, N = 100000, 1 thread, %s "
              "(each call from the same state over 0.5 s): ns per body-step; the share of the state stream\n",
              results.isa().c_str());
  for (const std::string p : {"float", "double"}) print_adaptive_row(results, noise, p);
}

}  // namespace kinema::bench::report
