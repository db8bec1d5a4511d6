// kinema_bench_report BENCH.json [CSV]: turns one kinema_bench run (Google Benchmark JSON,
// ideally with repetitions) into a table of ratios measured in that run: speed-ups over the
// naive and Odeint baselines, the fraction of the compute ceiling and of the streaming
// bandwidth reached, 2-thread scaling, and a verdict on whether 2-thread figures hold.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <regex>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace {

using json = nlohmann::json;

struct Figure {
  double median = 0;  // of the counter, over repetitions
  double cv = 0;      // coefficient of variation, 0 without repetitions
  double max = 0;     // the best repetition, where the run computed it (the machine's limits)
};

// run_name -> counter -> figure
using Runs = std::map<std::string, std::map<std::string, Figure>>;

Runs load_runs(const json& doc) {
  Runs runs;
  for (const json& b : doc.at("benchmarks")) {
    const std::string run = b.value("run_name", b.value("name", ""));
    const std::string aggregate = b.value("aggregate_name", "");
    if (b.value("run_type", "") == "aggregate" && aggregate != "median" && aggregate != "cv" && aggregate != "max") {
      continue;
    }
    if (b.contains("error_occurred") && b["error_occurred"].get<bool>()) continue;
    for (const auto& [key, value] : b.items()) {
      if (!value.is_number()) continue;
      Figure& f = runs[run][key];
      if (aggregate == "cv") {
        f.cv = value.get<double>();
      } else if (aggregate == "max") {
        f.max = value.get<double>();
      } else if (aggregate == "median" || aggregate.empty()) {
        f.median = value.get<double>();
      }
    }
  }
  return runs;
}

std::optional<Figure> find(const Runs& runs, const std::string& run, const char* counter) {
  const auto r = runs.find(run);
  if (r == runs.end()) return std::nullopt;
  const auto c = r->second.find(counter);
  if (c == r->second.end() || c->second.median == 0) return std::nullopt;
  return c->second;
}

std::string run_name(const std::string& kind, const std::string& method, const std::string& p,
                  const std::string& isa, int threads, long n) {
  return kind + "/" + method + "/" + p + "/" + isa + "/threads:" + std::to_string(threads) + "/" +
         std::to_string(n) + "/real_time";
}
std::string baseline(const char* name, const std::string& p, long n) {
  return std::string(name) + "/rk4/" + p + "/" + std::to_string(n) + "/real_time";
}
std::string stream(long n, int threads) {
  return "limit/stream/" + std::to_string(n) + "/real_time/threads:" + std::to_string(threads);
}
// The particle state's own traffic at n bodies (7 arrays read, 6 written), widest ISA, with
// each array asked for `ahead` bytes ahead (0: not at all).
std::string state_stream_run(const std::string& p, long n, long ahead, int threads) {
  return "limit/state_stream/" + p + "/" + std::to_string(n) + "/" + std::to_string(ahead) + "/real_time/threads:" +
         std::to_string(threads);
}
double value_bytes(const std::string& p) { return p == "float" ? 4 : 8; }
std::string peak(const std::string& p, int threads) {
  return "limit/fma_peak/" + p + "/real_time/threads:" + std::to_string(threads);
}

std::string cell(std::optional<double> x, const char* format) {
  if (!x || !std::isfinite(*x)) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, *x);
  return buf;
}

std::optional<double> percent(std::optional<double> x) {
  if (!x) return std::nullopt;
  return 100 * *x;
}

std::optional<double> median(std::optional<Figure> f) {
  if (!f) return std::nullopt;
  return f->median;
}

std::optional<double> ratio(std::optional<Figure> a, std::optional<Figure> b) {
  if (!a || !b) return std::nullopt;
  return a->median / b->median;
}

// Data cache sizes per level from the run's context (Google Benchmark reads them).
std::map<int, double> data_caches(const json& context) {
  std::map<int, double> sizes;
  for (const json& c : context.value("caches", json::array())) {
    if (c.value("type", "") != "Instruction") sizes[c.value("level", 0)] = c.value("size", 0.0);
  }
  return sizes;
}

class Report {
 public:
  Report(Runs runs, std::string isa, std::map<int, double> caches, std::FILE* csv)
      : runs_(std::move(runs)), isa_(std::move(isa)), caches_(std::move(caches)), csv_(csv) {}

  // Each method at each size against the limit that bounds it: the compute ceiling (the
  // kernel with its traffic removed) or the state stream at that size, whichever is slower.
  void bounds_table() {
    const long sizes[] = {16384L, 100000L, 4194304L};
    if (!find(runs_, run_name("fused", "euler", "float", isa_, 1, 4194304), "ns_per_body_step")) return;
    std::printf("\nWhat bounds each method, 1 thread, %s: ns per body-step, the bound (compute: the ceiling; "
                "L2 / L3 / DRAM: the state stream at that size) and the share of it reached\n", isa_.c_str());
    std::printf("%-6s %-16s", "prec", "method");
    for (long n : sizes) std::printf(" | %8ld: ns   bound    %%", n);
    std::printf("\n");
    for (const std::string p : {"float", "double"}) {
      for (const char* m : {"euler", "midpoint", "heun", "rk4", "symplectic_euler", "velocity_verlet"}) {
        std::printf("%-6s %-16s", p.c_str(), m);
        for (long n : sizes) bounds_cell(p, m, n);
        std::printf("\n");
      }
    }
    for (const std::string& line : below_70_) std::printf("%s\n", line.c_str());
  }

  // One step per frame, back to back and after idle gaps: default options against one thread,
  // default with prepare(), both threads on every step and a plain tbb::parallel_for.
  void frame_loop_table() {
    if (!frame_step(FrameRow{"float", 0, 16384}, "threads:1", "median")) return;
    std::printf("\nOne rk4 step per frame after an idle gap (0: back to back), %s: the median step over the run's "
                "frames, us (median of the runs); speed against 1 thread (the calling thread alone): back to back the ratio of the "
                "rows' medians, with gaps the median of the frame-by-frame ratios\n", isa_.c_str());
    std::printf("%-6s %6s %8s | %9s | %9s %4s %6s | %9s %6s | %9s %6s | %12s %6s\n", "prec", "gap us", "N",
                "1 thread", "default", "wkrs", "speed", "prepared", "speed", "2 threads", "speed", "parallel_for", "speed");
    Worst by_median, by_mean, against_peer;
    double same_low = 1e9, same_high = 0;  // N = 1024: one block, the same code in every variant
    for (int gap : {0, 1000, 8000}) {
      for (const std::string p : {"float", "double"}) {
        for (long n : {1024L, 4096L, 16384L, 65536L, 100000L, 1048576L}) frame_loop_row({p, gap, n}, by_median, by_mean, against_peer);
        for (const char* v : {"default", "prepared", "threads:2", "parallel_for"}) {
          if (const auto s = speed({p, gap, 1024}, v)) same_low = std::min(same_low, *s), same_high = std::max(same_high, *s);
        }
      }
    }
    std::printf("default: every hardware thread, the worker count measured by the stepper (wkrs: the count it "
                "favoured at the end, 0 = the calling thread alone); prepared: default with Stepper::prepare() "
                "right before each step, timed with it; 2 threads: both on every step. Back to back each variant "
                "is a row of its own; with gaps the variants take turns frame by frame in one row.\n"
                "worst default against 1 thread: %.2fx (%s); by mean step (every frame, pre-empted ones and retries "
                "of the other worker count too): %.2fx (%s); worst default against parallel_for at N >= 16384: %.2fx (%s)\n"
                "the run's noise: at N = 1024 every variant runs the same code on the calling thread (one block), and "
                "their speeds range %.2f-%.2fx\n",
                by_median.ratio, by_median.at.c_str(), by_mean.ratio, by_mean.at.c_str(), against_peer.ratio,
                against_peer.at.c_str(), same_low, same_high);
  }


  void rk4_table() {
    std::printf("\nFused RK4 (gravity + linear drag + spring), %s, ns per body-step; ratios from this run\n",
                isa_.c_str());
    std::printf("%-6s %8s | %12s %7s %7s %8s %6s | %12s %7s %6s\n", "prec", "N", "1 thread",
                "x naive", "x odeint", "ceiling", "BW", "2 threads", "scaling", "BW");
    for (const std::string p : {"float", "double"}) {
      for (long n : {1024L, 16384L, 100000L, 1048576L, 4194304L}) rk4_row(p, n);
    }
    std::printf("ceiling: the same kernel with its memory traffic removed (each cache-resident block "
                "takes all steps in turn), as ceiling time / step time.\nBW: state bytes read + "
                "written per second against the state's own stream (the same 7 arrays read and 6 "
                "written, almost no arithmetic, %s; the best repetition at the fastest of three prefetch distances) at the same size, precision and thread count.\n"
                "2 threads: every step on both (workers = all); at N = 1024 the set is one block, "
                "run on the calling thread.\n", isa_.c_str());
  }

  void methods_table() {
    std::printf("\nEvery method, N = 100000, 1 thread, %s: ns per body-step (ceiling fraction)\n",
                isa_.c_str());
    for (const std::string p : {"float", "double"}) {
      std::printf("%-6s", p.c_str());
      for (const char* m : {"euler", "midpoint", "heun", "rk4", "symplectic_euler", "velocity_verlet"}) {
        const auto f = find(runs_, run_name("fused", m, p, isa_, 1, 100000), "ns_per_body_step");
        const auto c = find(runs_, run_name("ceiling", m, p, isa_, 1, 100000), "ns_per_body_step");
        std::printf("  %s %s (%s)", m, cell(median(f), "%.3f").c_str(),
                    cell(percent(ratio(c, f)), "%.0f%%").c_str());
      }
      std::printf("\n");
    }
  }

  void isa_table() {
    std::printf("\nRK4, N = 100000, 1 thread, by instruction set: ns per body-step (speed-up over scalar)\n");
    for (const std::string p : {"float", "double"}) {
      const auto scalar = find(runs_, run_name("fused", "rk4", p, "scalar", 1, 100000), "ns_per_body_step");
      std::printf("%-6s", p.c_str());
      for (const char* isa : {"scalar", "sse2", "avx2", "avx512"}) {
        const auto f = find(runs_, run_name("fused", "rk4", p, isa, 1, 100000), "ns_per_body_step");
        if (!f) continue;
        std::printf("  %s %.3f (%s)", isa, f->median, cell(ratio(scalar, f), "%.1fx").c_str());
      }
      std::printf("\n");
    }
  }

  void rigid_table() {
    std::printf("\nRigid bodies, RK4, %s: ns per body-step (cost relative to a particle); the kernel's 597 flops "
                "per body-step (FMA = 2) as a share of the FMA peak at that thread count\n", isa_.c_str());
    for (const std::string p : {"float", "double"}) {
      for (int threads : {1, 2}) {
        const std::string suffix = "/" + isa_ + "/threads:" + std::to_string(threads) + "/100000/real_time";
        const auto rigid = find(runs_, "rigid/rk4/" + p + suffix, "ns_per_body_step");
        const auto ceiling = find(runs_, "rigid-ceiling/rk4/" + p + suffix, "ns_per_body_step");
        const auto particle = find(runs_, run_name("fused", "rk4", p, isa_, threads, 100000), "ns_per_body_step");
        if (!rigid) continue;
        const auto flops = find(runs_, "rigid/rk4/" + p + suffix, "GFLOP_per_s");
        std::printf("%-6s N = 100000, %d thread%s: %.3f (%s a particle step; ceiling %s; %s of the FMA peak)\n",
                    p.c_str(), threads, threads > 1 ? "s" : "", rigid->median,
                    cell(ratio(rigid, particle), "%.1fx").c_str(), cell(percent(ratio(ceiling, rigid)), "%.0f%%").c_str(),
                    cell(percent(ratio(flops, find(runs_, peak(p, threads), "GFLOP_per_s"))), "%.0f%%").c_str());
      }
    }
  }

  void coupled_table() {
    const auto baseline = find(runs_, "baseline/nbody_scalar_double/4096/real_time", "interactions_per_s");
    if (!find(runs_, nbody_run("float", 1, 4096), "interactions_per_s")) return;
    std::printf("\nN-body gravity, %s, one Euler step = n^2 interactions (20 flops each)\n", isa_.c_str());
    std::printf("%-6s %6s | %13s %8s %9s | %13s %7s\n", "prec", "N", "1 thread", "FMA peak",
                "x scalar", "2 threads", "scaling");
    for (const std::string p : {"float", "double"}) {
      for (long n : {4096L, 16384L}) {
        const auto one = find(runs_, nbody_run(p, 1, n), "interactions_per_s");
        const auto two = find(runs_, nbody_run(p, 2, n), "interactions_per_s");
        if (!one) continue;
        cvs_.push_back(one->cv);
        const auto flops = find(runs_, nbody_run(p, 1, n), "GFLOP_per_s");
        std::printf("%-6s %6ld | %9.3f G/s %8s %9s | %9s G/s %7s\n", p.c_str(), n, one->median * 1e-9,
                    cell(percent(ratio(flops, find(runs_, peak(p, 1), "GFLOP_per_s"))), "%.0f%%").c_str(),
                    cell(ratio(one, baseline), "%.1fx").c_str(), cell(two ? two->median * 1e-9 : NAN, "%.3f").c_str(),
                    cell(ratio(two, one), "%.2fx").c_str());
      }
    }
    std::printf("FMA peak: the 1-thread peak of the same precision in this run; x scalar: against a plain "
                "double loop over (i, j) built for baseline x86-64 (N = 4096).\n");
    const std::string kernel = "springs/float/" + isa_ + "/512/real_time";
    const auto springs = find(runs_, kernel, "ns_per_spring");
    if (!springs) return;
    cvs_.push_back(springs->cv);
    const auto bw = ratio(find(runs_, kernel, "GB_per_s"), find(runs_, stream(1382400, 1), "GB_per_s"));
    std::printf("Cloth 512 x 512 (1.05M springs), float: the spring kernel %.3f ns per spring (%s GB/s, %s of "
                "in-place streaming over the same 38.7 MB); a whole Euler step %s / %s ns per spring on 1 / 2 threads\n",
                springs->median, value(kernel, "GB_per_s").c_str(), cell(percent(bw), "%.0f%%").c_str(),
                value("cloth/float/" + isa_ + "/threads:1/512/real_time", "ns_per_spring", "%.3f").c_str(),
                value("cloth/float/" + isa_ + "/threads:2/512/real_time", "ns_per_spring", "%.3f").c_str());
  }

  void frame_table() {
    const auto copy_f = find(runs_, "frame/copy/float/100000/real_time", "ns_per_body_step");
    if (!copy_f) return;
    std::printf("\nA frame at N = 100000, 1 thread, %s (previous = current, one rk4 step, interpolate): "
                "ns per body-frame (times a plain copy of the set)\n", isa_.c_str());
    for (const std::string p : {"float", "double"}) {
      const auto frame = find(runs_, "frame/" + p + "/" + isa_ + "/100000/real_time", "ns_per_body_step");
      const auto copy = find(runs_, "frame/copy/" + p + "/100000/real_time", "ns_per_body_step");
      if (!frame) continue;
      cvs_.push_back(frame->cv);
      std::printf("%-6s %.3f (%s; the copy alone %s)\n", p.c_str(), frame->median,
                  cell(ratio(frame, copy), "%.1fx").c_str(), cell(median(copy), "%.3f").c_str());
    }
  }

  void guard_table() {
    if (!find(runs_, "guard/float/off/" + isa_ + "/100000/real_time", "ns_per_body_step")) return;
    std::printf("\nThe finiteness guard, one rk4 step per call, 1 thread, %s: ns per body-step (times the "
                "guard off); the guard's own traffic (a copy of 6 arrays, a scan of 6) at this size's state-stream speed\n", isa_.c_str());
    for (const std::string p : {"float", "double"}) {
      for (long n : {100000L, 1L << 20}) {
        const std::string at = "/" + isa_ + "/" + std::to_string(n) + "/real_time";
        const auto off = find(runs_, "guard/" + p + "/off" + at, "ns_per_body_step");
        if (!off) continue;
        const auto check = find(runs_, "guard/" + p + "/check" + at, "ns_per_body_step");
        const auto clamp = find(runs_, "guard/" + p + "/clamp" + at, "ns_per_body_step");
        // Bytes per body the guard moves (12 arrays read, 6 written) over bytes per ns.
        const auto s = state_stream(p, n, 1);
        const double pass_ns = s ? 18.0 * (p == "float" ? 4 : 8) / s->median : 0;
        for (const auto& r : {off, check, clamp}) {
          if (r) cvs_.push_back(r->cv);
        }
        std::printf("%-6s %8ld | off %.3f | check %s (%s) | clamp %s (%s) | guard traffic %s\n", p.c_str(), n,
                    off->median, cell(median(check), "%.3f").c_str(), cell(ratio(check, off), "%.2fx").c_str(),
                    cell(median(clamp), "%.3f").c_str(), cell(ratio(clamp, off), "%.2fx").c_str(),
                    pass_ns > 0 ? cell(pass_ns, "%.3f").c_str() : "-");
      }
    }
  }

  void adaptive_table() {
    if (!find(runs_, "adaptive/dopri5/float/" + isa_ + "/100000/real_time", "ns_per_body_step")) return;
    std::printf("\nError-controlled dopri5 against fixed steps at its mean accepted step, N = 100000, 1 thread, %s "
                "(each call from the same state over 0.5 s): ns per body-step; the share of the state stream\n",
                isa_.c_str());
    for (const std::string p : {"float", "double"}) {
      const std::string at = "/" + isa_ + "/100000/real_time";
      const auto adaptive = find(runs_, "adaptive/dopri5/" + p + at, "ns_per_body_step");
      const auto fixed = find(runs_, "fixed/dopri5/" + p + at, "ns_per_body_step");
      if (!adaptive) continue;
      cvs_.push_back(adaptive->cv);
      const auto bw = ratio(find(runs_, "adaptive/dopri5/" + p + at, "GB_per_s"), state_stream(p, 100000, 1));
      std::printf("%-6s adaptive %.3f (%s steps per call) | fixed %s | adaptive / fixed %s | %s of the stream\n",
                  p.c_str(), adaptive->median, value("adaptive/dopri5/" + p + at, "accepted_per_call", "%.0f").c_str(),
                  cell(median(fixed), "%.3f").c_str(), cell(ratio(adaptive, fixed), "%.2fx").c_str(),
                  cell(percent(bw), "%.1f%%").c_str());
    }
  }

  void paired_scaling() {
    bool header = false;
    for (const std::string p : {"float", "double"}) {
      const std::string run = "scaling/rk4/" + p + "/" + isa_ + "/100000";
      const auto kept = find(runs_, run, "scaling");
      const auto all = find(runs_, run, "scaling_all_pairs");
      if (!all) continue;
      if (!header) {
        std::printf("\n2 threads against 1, fused RK4, N = 100000, %s, measured in pairs (a few steps on 1 "
                    "thread, then on 2; pure FMA work probed before and after each pair)\n", isa_.c_str());
        header = true;
      }
      std::printf("%-6s %s in the pairs where FMA work scaled 1.8x or more (%s of %s pairs; FMA %s), "
                  "%s over all pairs\n",
                  p.c_str(), cell(median(kept), "%.2fx").c_str(), value(run, "pairs_kept", "%.0f").c_str(),
                  value(run, "pairs", "%.0f").c_str(), value(run, "fma_scaling", "%.2fx").c_str(),
                  cell(median(all), "%.2fx").c_str());
    }
  }

  void limits() {
    std::printf("\nMachine limits in this run: FMA peak float %s / %s GFLOP/s (1 / 2 threads), double %s / %s;"
                "\n  the state stream at 4M float bodies (%s): %s / %s GB/s (2 threads: Google Benchmark averages each "
                "thread's own time, so a limit measured on threads that did not overlap reads high)\n",
                value(peak("float", 1), "GFLOP_per_s").c_str(), value(peak("float", 2), "GFLOP_per_s").c_str(),
                value(peak("double", 1), "GFLOP_per_s").c_str(), value(peak("double", 2), "GFLOP_per_s").c_str(),
                isa_.c_str(), cell(median(state_stream("float", 4194304, 1)), "%.1f").c_str(),
                cell(median(state_stream("float", 4194304, 2)), "%.1f").c_str());
    const auto one = find(runs_, peak("float", 1), "GFLOP_per_s");
    const auto two = find(runs_, peak("float", 2), "GFLOP_per_s");
    if (one && two) {
      const double s = two->median / one->median;
      std::printf("scaling check: pure FMA work runs %.2fx faster on 2 threads: %s\n", s,
                  s >= 1.8 ? "two real cores, the 2-thread figures are trustworthy"
                           : "below 1.8x, the vCPUs share a core now; discard the 2-thread figures");
    }
    // The probes of the paired runs sample the whole run, not one moment of it.
    for (const std::string p : {"float", "double"}) {
      const std::string run = "scaling/rk4/" + p + "/" + isa_ + "/100000";
      const auto fma = find(runs_, run, "fma_scaling");
      if (fma && fma->median < 1.8) {
        std::printf("but the FMA probes of the %s pairs scaled only %.2fx (median): the vCPUs shared a core "
                    "for much of the run; trust only the paired figures\n", p.c_str(), fma->median);
      }
    }
  }

  void noise() const {
    double max_cv = 0, sum = 0;
    for (double cv : cvs_) max_cv = std::max(max_cv, cv), sum += cv;
    if (!cvs_.empty()) {
      std::printf("noise: coefficient of variation over repetitions, mean %.1f%%, max %.1f%% "
                  "(differences below that are noise)\n",
                  100 * sum / double(cvs_.size()), 100 * max_cv);
    }
  }

 private:
  std::string nbody_run(const std::string& p, int threads, long n) const {
    return "nbody/" + p + "/" + isa_ + "/threads:" + std::to_string(threads) + "/" + std::to_string(n) + "/real_time";
  }

  struct FrameRow {
    std::string p;
    int gap;
    long n;
  };
  struct Worst {
    double ratio = 1e9;
    std::string at;
    void see(double r, const FrameRow& row) {
      if (r >= ratio) return;
      ratio = r;
      at = row.p + " N = " + std::to_string(row.n) + " gap " + std::to_string(row.gap) + " us";
    }
  };

  // A variant's median or mean step at a row, ns per body-step: back to back from its own
  // row, with gaps from the interleaved row's counters.
  std::optional<Figure> frame_step(const FrameRow& r, const char* variant, const char* statistic) const {
    const std::string n = std::to_string(r.n);
    if (r.gap == 0) {
      const std::string run = "frame_loop/" + r.p + "/gap_us:0/" + variant + "/" + n + "/manual_time";
      return find(runs_, run, std::string(statistic) == "median" ? "median_ns_per_body_step" : "ns_per_body_step");
    }
    const std::string rounds = r.gap >= 8000 ? "60" : "120";
    const std::string run = "frame_loop/" + r.p + "/gap_us:" + std::to_string(r.gap) + "/interleaved/" + n +
                            "/iterations:" + rounds + "/manual_time";
    return find(runs_, run, (std::string(statistic) + ":" + variant).c_str());
  }

  std::string frame_workers(const FrameRow& r) const {
    const std::string n = std::to_string(r.n);
    const std::string run = r.gap == 0 ? "frame_loop/" + r.p + "/gap_us:0/default/" + n + "/manual_time"
                                       : "frame_loop/" + r.p + "/gap_us:" + std::to_string(r.gap) + "/interleaved/" +
                                             n + "/iterations:" + (r.gap >= 8000 ? "60" : "120") + "/manual_time";
    return workers(run);
  }

  // Speed against one thread: with gaps the median of the round-by-round ratios (paired),
  // back to back the ratio of the rows' medians.
  std::optional<double> speed(const FrameRow& r, const char* variant) const {
    if (r.gap > 0) return median(frame_step(r, variant, "speed"));
    return ratio(frame_step(r, "threads:1", "median"), frame_step(r, variant, "median"));
  }

  void frame_loop_row(const FrameRow& r, Worst& by_median, Worst& by_mean, Worst& against_peer) {
    const auto one = frame_step(r, "threads:1", "median");
    const auto measured = frame_step(r, "default", "median");
    const auto prepared = frame_step(r, "prepared", "median");
    const auto two = frame_step(r, "threads:2", "median");
    const auto peer = frame_step(r, "parallel_for", "median");
    if (!one || !measured) return;
    cvs_.push_back(one->cv);
    cvs_.push_back(measured->cv);
    if (const auto s = speed(r, "default")) by_median.see(*s, r);
    const auto one_mean = frame_step(r, "threads:1", "mean"), measured_mean = frame_step(r, "default", "mean");
    if (one_mean && measured_mean) by_mean.see(one_mean->median / measured_mean->median, r);
    if (r.n >= 16384 && peer) against_peer.see(peer->median / measured->median, r);
    const double us = double(r.n) * 1e-3;
    const auto in_us = [&](const std::optional<Figure>& f) { return cell(f ? f->median * us : NAN, "%.2f"); };
    std::printf("%-6s %6d %8ld | %9s | %9s %4s %6s | %9s %6s | %9s %6s | %12s %6s\n", r.p.c_str(), r.gap, r.n,
                in_us(one).c_str(), in_us(measured).c_str(), frame_workers(r).c_str(),
                cell(speed(r, "default"), "%.2fx").c_str(), in_us(prepared).c_str(), cell(speed(r, "prepared"), "%.2fx").c_str(),
                in_us(two).c_str(), cell(speed(r, "threads:2"), "%.2fx").c_str(), in_us(peer).c_str(),
                cell(speed(r, "parallel_for"), "%.2fx").c_str());
  }


  // The state stream's limit: its best repetition at the fastest of its prefetch distances
  // (none, 1 KiB, 4 KiB).
  std::optional<Figure> state_stream(const std::string& p, long n, int threads) const {
    std::optional<Figure> best;
    for (long ahead : {0L, 1024L, 4096L}) {
      auto f = find(runs_, state_stream_run(p, n, ahead, threads), "GB_per_s");
      if (!f) continue;
      f->median = std::max(f->median, f->max);
      if (!best || f->median > best->median) best = f;
    }
    return best;
  }

  // The worker count a frame-loop row's stepper favoured (0 is a value here, not a gap).
  std::string workers(const std::string& run) const {
    const auto r = runs_.find(run);
    if (r == runs_.end() || !r->second.count("workers")) return "-";
    return cell(r->second.at("workers").median, "%.0f");
  }

  // Where a state of n bodies of precision p lives: the smallest data cache holding it.
  std::string level(const std::string& p, long n) const {
    const double bytes = 7 * value_bytes(p) * double(n);
    for (const auto& [l, size] : caches_) {
      if (l >= 2 && bytes <= size) return l == 2 ? "L2" : l == 3 ? "L3" : "L4";
    }
    return "DRAM";
  }

  void bounds_cell(const std::string& p, const char* m, long n) {
    const auto f = find(runs_, run_name("fused", m, p, isa_, 1, n), "ns_per_body_step");
    const auto c = find(runs_, run_name("ceiling", m, p, isa_, 1, 100000), "ns_per_body_step");
    const auto s = state_stream(p, n, 1);
    if (!f || !c || !s) return void(std::printf(" | %26s", "-"));
    cvs_.push_back(f->cv);
    const double memory_ns = 13 * value_bytes(p) / s->median;
    const bool compute = c->median >= memory_ns;
    const double bound = compute ? c->median : memory_ns;
    const std::string kind = compute ? "compute" : level(p, n);
    const double share = bound / f->median;
    std::printf(" | %14.3f %7s %4.0f", f->median, kind.c_str(), 100 * share);
    if (share < 0.7) {
      char line[256];
      std::snprintf(line, sizeof line, "below 70%%: %s %s at %ld: %.3f ns against %s %.3f (ceiling %.3f, state stream %.3f)",
                    p.c_str(), m, n, f->median, kind.c_str(), bound, c->median, memory_ns);
      below_70_.push_back(line);
    }
  }

  std::string value(const std::string& run, const char* counter, const char* format = "%.1f") const {
    const auto f = find(runs_, run, counter);
    return f ? cell(f->median, format) : "-";
  }

  void rk4_row(const std::string& p, long n) {
    const auto one = find(runs_, run_name("fused", "rk4", p, isa_, 1, n), "ns_per_body_step");
    if (!one) return;
    cvs_.push_back(one->cv);
    const auto two = find(runs_, run_name("fused", "rk4", p, isa_, 2, n), "ns_per_body_step");
    const auto naive = find(runs_, baseline("naive_aos", p, n), "ns_per_body_step");
    const auto odeint = find(runs_, baseline("odeint", p, n), "ns_per_body_step");
    const auto ceiling = find(runs_, run_name("ceiling", "rk4", p, isa_, 1, 100000), "ns_per_body_step");
    const auto bw1 = ratio(find(runs_, run_name("fused", "rk4", p, isa_, 1, n), "GB_per_s"),
                           state_stream(p, n, 1));
    const auto bw2 = ratio(find(runs_, run_name("fused", "rk4", p, isa_, 2, n), "GB_per_s"),
                           state_stream(p, n, 2));
    std::printf("%-6s %8ld | %7.3f ±%2.0f%% %7s %8s %8s %6s | %12s %7s %6s\n", p.c_str(), n, one->median,
                100 * one->cv, cell(ratio(naive, one), "%.1fx").c_str(),
                cell(ratio(odeint, one), "%.1fx").c_str(), cell(percent(ratio(ceiling, one)), "%.0f%%").c_str(),
                cell(percent(bw1), "%.0f%%").c_str(), cell(median(two), "%.3f").c_str(),
                cell(ratio(one, two), "%.2fx").c_str(), cell(percent(bw2), "%.0f%%").c_str());
    if (csv_ != nullptr) {
      std::fprintf(csv_, "%s,%ld,%s,%.6g,%.4g,%s,%s,%s,%s,%s,%s,%s\n", p.c_str(), n, isa_.c_str(),
                   one->median, one->cv, cell(median(two), "%.6g").c_str(),
                   cell(ratio(naive, one), "%.4g").c_str(), cell(ratio(odeint, one), "%.4g").c_str(),
                   cell(ratio(ceiling, one), "%.4g").c_str(), cell(bw1, "%.4g").c_str(),
                   cell(bw2, "%.4g").c_str(), cell(ratio(one, two), "%.4g").c_str());
    }
  }

  Runs runs_;
  std::string isa_;
  std::map<int, double> caches_;
  std::FILE* csv_;
  std::vector<double> cvs_;
  std::vector<std::string> below_70_;
};

// Google Benchmark writes a counter's undefined statistics (the cv of a counter that is 0 in
// every repetition) as NaN or inf, which JSON has no word for: read those as null.
json parse_benchmark_json(const char* path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open the file");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  static const std::regex undefined(R"(:\s*-?(NaN|nan|inf|Infinity)\b)");
  return json::parse(std::regex_replace(text, undefined, ": null"));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: kinema_bench_report BENCH.json [TABLE.csv]\n");
    return 2;
  }
  json doc;
  try {
    doc = parse_benchmark_json(argv[1]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kinema_bench_report: %s: %s\n", argv[1], e.what());
    return 1;
  }
  const json& context = doc.at("context");
  const std::string isa = context.value("kinema_best_isa", "avx512");
  std::printf("kinema benchmarks on %s (cpu family %s, %d threads), %s; kernels use %s\n",
              context.value("cpu_model", "?").c_str(), context.value("cpu_family", "?").c_str(),
              context.value("num_cpus", 0), context.value("date", "?").c_str(), isa.c_str());
  std::FILE* csv = argc > 2 ? std::fopen(argv[2], "w") : nullptr;
  if (csv != nullptr) {
    std::fprintf(csv, "precision,n,isa,ns_per_body_step,cv,ns_per_body_step_2t,speedup_naive,"
                      "speedup_odeint,ceiling_fraction,bandwidth_fraction,bandwidth_fraction_2t,"
                      "scaling_2t\n");
  }
  Report report(load_runs(doc), isa, data_caches(context), csv);
  report.rk4_table();
  report.methods_table();
  report.bounds_table();
  report.frame_loop_table();
  report.isa_table();
  report.rigid_table();
  report.paired_scaling();
  report.coupled_table();
  report.frame_table();
  report.guard_table();
  report.adaptive_table();
  report.limits();
  report.noise();
  if (csv != nullptr) std::fclose(csv);
  return 0;
}
