// Coupled terms: N-body gravity against the FMA peak and a scalar loop, and the cloth's
// spring kernel against in-place streaming over the same bytes.
#include <cmath>
#include <cstdio>

#include "machine_limits.hpp"
#include "names.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

// p: float, float-fast or double; the FMA peak is its precision's.
void print_nbody_row(const Results& results, Noise& noise, const std::string& p, long n) {
  const std::string precision = p == "double" ? p : "float";
  const auto one = results.find(nbody_run(p, results.isa(), 1, n), "interactions_per_s");
  const auto two = results.find(nbody_run(p, results.isa(), 2, n), "interactions_per_s");
  if (!one) return;
  noise.add(one->cv);
  const auto flops = results.find(nbody_run(p, results.isa(), 1, n), "GFLOP_per_s");
  const auto scalar = results.find("baseline/nbody_scalar_double/4096/real_time", "interactions_per_s");
  std::printf("%-10s %6ld | %9.3f G/s %8s %9s | %9s G/s %7s\n", p.c_str(), n, one->median * 1e-9,
              cell(percent(ratio(flops, fma_peak(results, precision, 1))), "%.0f%%").c_str(),
              cell(ratio(one, scalar), "%.1fx").c_str(), cell(two ? two->median * 1e-9 : NAN, "%.3f").c_str(),
              cell(ratio(two, one), "%.2fx").c_str());
}

std::string fast_ratio(const Results& results, long n) {
  const auto fast = results.find(nbody_run("float-fast", results.isa(), 1, n), "interactions_per_s");
  return cell(ratio(fast, results.find(nbody_run("float", results.isa(), 1, n), "interactions_per_s")), "%.2fx");
}

void print_cloth_line(const Results& results, Noise& noise) {
  const std::string kernel = "springs/float/" + results.isa() + "/512/real_time";
  const auto springs = results.find(kernel, "ns_per_spring");
  if (!springs) return;
  noise.add(springs->cv);
  const auto bw = ratio(results.find(kernel, "GB_per_s"), results.find(stream_run(1382400, 1), "GB_per_s"));
  const std::string cloth = "cloth/float/" + results.isa() + "/threads:";
  std::printf("Cloth 512 x 512 (1.05M springs), float: the spring kernel %.3f ns per spring (%s GB/s, %s of "
              "in-place streaming over the same 38.7 MB); a whole Euler step %s / %s ns per spring on 1 / 2 threads\n",
              springs->median, results.value(kernel, "GB_per_s").c_str(), cell(percent(bw), "%.0f%%").c_str(),
              results.value(cloth + "1/512/real_time", "ns_per_spring", "%.3f").c_str(),
              results.value(cloth + "2/512/real_time", "ns_per_spring", "%.3f").c_str());
}

// Implicit frames of the 256 x 256 cloths against Verlet at its stable step, and one Jacobi
// CG iteration against in-place streaming over its working set.
void print_implicit_cloth(const Results& results, Noise& noise, const std::string& cloth, const char* title) {
  const auto run = [&](const std::string& m) { return "implicit/" + cloth + "/" + m + "/256/real_time"; };
  const auto verlet = results.find(run("velocity_verlet"), "s_per_simulated_s");
  if (!verlet) return;
  noise.add(verlet->cv);
  std::printf("%s, float, 1 thread, seconds per simulated second: velocity Verlet at its stable step %.3f (%s steps "
              "a frame)",
              title, verlet->median, results.value(run("velocity_verlet"), "steps_per_frame", "%.0f").c_str());
  for (const std::string m : {"implicit_euler", "implicit_euler-tol-0.01", "implicit_euler-tol-1e-5", "implicit_euler-jacobi", "ros2"}) {
    const auto frames = results.find(run(m), "s_per_simulated_s");
    if (!frames) continue;
    noise.add(frames->cv);
    std::printf("; %s at dt 1/60 %.3f (%s, %s CG iterations a frame", m.c_str(), frames->median,
                cell(ratio(frames, verlet), "%.2fx").c_str(), results.value(run(m), "cg_per_frame", "%.1f").c_str());
    const auto bw = ratio(results.find(run(m), "GB_per_s"), results.find(stream_run(608549, 1), "GB_per_s"));
    if (bw) {
      std::printf(", one at %s ns a body, %s of in-place streaming over its 17.0 MB",
                  results.value(run(m), "ns_per_body_iteration", "%.1f").c_str(), cell(percent(bw), "%.0f%%").c_str());
    }
    std::printf(")");
  }
  std::printf("\n");
}

void print_implicit_lines(const Results& results, Noise& noise) {
  print_implicit_cloth(results, noise, "cloth", "Stiff cloth 256 x 256 (the shipped cloth's masses, |lambda| ~ 1790/s)");
  print_implicit_cloth(results, noise, "cloth-4x", "The shipped cloth at 4x resolution (256 x 256, |lambda| 4x as large)");
}

}  // namespace

void print_coupled_table(const Results& results, Noise& noise) {
  if (!results.find(nbody_run("float", results.isa(), 1, 4096), "interactions_per_s")) return print_implicit_lines(results, noise);
  std::printf("\nN-body gravity, %s, one Euler step = n^2 interactions (20 flops each)\n", results.isa().c_str());
  std::printf("%-10s %6s | %13s %8s %9s | %13s %7s\n", "prec", "N", "1 thread", "FMA peak", "x scalar",
              "2 threads", "scaling");
  for (const std::string p : {"float", "float-fast", "double"}) {
    for (long n : {4096L, 16384L}) print_nbody_row(results, noise, p, n);
  }
  std::printf("FMA peak: the 1-thread peak of the same precision in this run; x scalar: against a plain "
              "double loop over (i, j) built for baseline x86-64 (N = 4096); float-fast: NBody::fast, at\n"
              "%s / %s the exact float kernel's interactions per second (N = 4096 / 16384, 1 thread).\n",
              fast_ratio(results, 4096).c_str(), fast_ratio(results, 16384).c_str());
  print_cloth_line(results, noise);
  print_implicit_lines(results, noise);
}

}  // namespace kinema::bench::report
