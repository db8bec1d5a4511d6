// One rk4 step per frame, back to back and after idle gaps: default options against one
// thread, default with prepare(), both threads on every step and a plain tbb::parallel_for.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "names.hpp"
#include "tables.hpp"

namespace kinema::bench::report {
namespace {

const int kGaps[] = {0, 1000, 8000};
const long kSizes[] = {1024L, 4096L, 16384L, 65536L, 100000L, 1048576L};
const char* const kVariants[] = {"default", "prepared", "threads:2", "parallel_for"};

struct FrameRow {
  std::string p;
  int gap;
  long n;
};

// The lowest ratio seen and the row it was seen at.
struct Worst {
  double ratio = 1e9;
  std::string at;
  void see(double r, const FrameRow& row) {
    if (r >= ratio) return;
    ratio = r;
    at = row.p + " N = " + std::to_string(row.n) + " gap " + std::to_string(row.gap) + " us";
  }
  std::string text() const {
    if (at.empty()) return "-";
    char buf[128];
    std::snprintf(buf, sizeof buf, "%.2fx (%s)", ratio, at.c_str());
    return buf;
  }
};

struct Summary {
  Worst by_median, by_mean, against_peer;
  double same_low = 1e9, same_high = 0;  // N = 1024: one block, the same code in every variant
  bool same_seen() const { return same_high > 0; }
};

// A variant's median or mean step at a row, ns per body-step: back to back from its own
// row, with gaps from the interleaved row's counters.
std::optional<Figure> frame_step(const Results& results, const FrameRow& r, const char* variant,
                                 const std::string& statistic) {
  const std::string run = frame_loop_run(r.p, r.gap, variant, r.n);
  if (r.gap > 0) return results.find(run, (statistic + ":" + variant).c_str());
  return results.find(run, statistic == "median" ? "median_ns_per_body_step" : "ns_per_body_step");
}

// Speed against one thread: with gaps the median of the round-by-round ratios (paired),
// back to back the ratio of the rows' medians.
std::optional<double> speed(const Results& results, const FrameRow& r, const char* variant) {
  if (r.gap > 0) return median(frame_step(results, r, variant, "speed"));
  return ratio(frame_step(results, r, "threads:1", "median"), frame_step(results, r, variant, "median"));
}

// The worker count the row's default stepper favoured (0 is a value here, not a gap).
std::string frame_workers(const Results& results, const FrameRow& r) {
  return cell(results.count(frame_loop_run(r.p, r.gap, "default", r.n), "workers"), "%.0f");
}

void see_worst(const Results& results, const FrameRow& r, Summary& summary) {
  if (const auto s = speed(results, r, "default")) summary.by_median.see(*s, r);
  const auto one_mean = frame_step(results, r, "threads:1", "mean");
  const auto measured_mean = frame_step(results, r, "default", "mean");
  if (one_mean && measured_mean) summary.by_mean.see(one_mean->median / measured_mean->median, r);
  // With gaps the peer has a row of its own: each paired against its own row's one thread.
  if (r.n < 16384) return;
  if (r.gap > 0) {
    const auto peer = speed(results, r, "parallel_for"), measured = speed(results, r, "default");
    if (peer && measured) summary.against_peer.see(*measured / *peer, r);
    return;
  }
  const auto peer = frame_step(results, r, "parallel_for", "median");
  const auto measured = frame_step(results, r, "default", "median");
  if (peer && measured) summary.against_peer.see(peer->median / measured->median, r);
}

void print_frame_loop_row(const Results& results, const FrameRow& r, Noise& noise, Summary& summary) {
  const auto one = frame_step(results, r, "threads:1", "median");
  const auto measured = frame_step(results, r, "default", "median");
  if (!one || !measured) return;
  noise.add(one->cv);
  noise.add(measured->cv);
  see_worst(results, r, summary);
  const double us = double(r.n) * 1e-3;
  const auto in_us = [&](const char* v) {
    const auto f = frame_step(results, r, v, "median");
    return cell(f ? f->median * us : NAN, "%.2f");
  };
  const auto speed_of = [&](const char* v) { return cell(speed(results, r, v), "%.2fx"); };
  const auto spin = results.count(frame_loop_run(r.p, r.gap, "default", r.n), "spin_us_per_frame");
  std::printf("%-6s %6d %8ld | %9s | %9s %4s %6s | %9s %6s | %9s %6s | %12s %6s | %6s\n", r.p.c_str(), r.gap, r.n,
              in_us("threads:1").c_str(), in_us("default").c_str(), frame_workers(results, r).c_str(),
              speed_of("default").c_str(), in_us("prepared").c_str(), speed_of("prepared").c_str(),
              in_us("threads:2").c_str(), speed_of("threads:2").c_str(), in_us("parallel_for").c_str(),
              speed_of("parallel_for").c_str(), cell(spin, "%.0f").c_str());
}

// At N = 1024 every variant runs the same code: their spread is the run's own noise.
void see_same_code(const Results& results, const FrameRow& r, Summary& summary) {
  for (const char* v : kVariants) {
    if (const auto s = speed(results, r, v)) {
      summary.same_low = std::min(summary.same_low, *s), summary.same_high = std::max(summary.same_high, *s);
    }
  }
}

void print_frame_loop_header(const std::string& isa) {
  std::printf("\nOne rk4 step per frame after an idle gap (0: back to back), %s: the median step over the run's "
              "frames, us (median of the runs); speed against 1 thread (the calling thread alone): back to back the ratio of the "
              "rows' medians, with gaps the median of the paired frame ratios; spin: the default job system's workers spinning, "
              "us of CPU per frame\n", isa.c_str());
  std::printf("%-6s %6s %8s | %9s | %9s %4s %6s | %9s %6s | %9s %6s | %12s %6s | %6s\n", "prec", "gap us", "N",
              "1 thread", "default", "wkrs", "speed", "prepared", "speed", "2 threads", "speed", "parallel_for", "speed",
              "spin");
}

void print_frame_loop_notes(const Summary& s) {
  std::printf("default: every hardware thread, the worker count measured by the stepper (wkrs: the count it "
              "favoured at the end, 0 = the calling thread alone); prepared: default with Stepper::prepare() "
              "right before each step, timed with it; 2 threads: both on every step. Back to back each variant "
              "is a row of its own; with gaps kinema's variants take turns in runs of 8 frames in one row, and "
              "parallel_for with 1 thread in another (in one row, the two oneTBB users starved each other).\n"
              "worst default against 1 thread: %s; by mean step (every frame, pre-empted ones and retries "
              "of the other worker count too): %s; worst default against parallel_for at N >= 16384 (with gaps: "
              "their speeds against their own rows' 1 thread): %s\n",
              s.by_median.text().c_str(), s.by_mean.text().c_str(), s.against_peer.text().c_str());
  if (!s.same_seen()) return;
  std::printf("the run's noise: at N = 1024 every variant runs the same code on the calling thread (one block), and "
              "their speeds range %.2f-%.2fx\n", s.same_low, s.same_high);
}

bool has_frame_loop(const Results& results) {
  for (int gap : kGaps) {
    for (const std::string p : {"float", "double"}) {
      for (long n : kSizes) {
        const FrameRow r{p, gap, n};
        if (frame_step(results, r, "threads:1", "median") && frame_step(results, r, "default", "median")) return true;
      }
    }
  }
  return false;
}

}  // namespace

void print_frame_loop_table(const Results& results, Noise& noise) {
  if (!has_frame_loop(results)) return;
  print_frame_loop_header(results.isa());
  Summary summary;
  for (int gap : kGaps) {
    for (const std::string p : {"float", "double"}) {
      for (long n : kSizes) print_frame_loop_row(results, {p, gap, n}, noise, summary);
      see_same_code(results, {p, gap, 1024}, summary);
    }
  }
  print_frame_loop_notes(summary);
}

}  // namespace kinema::bench::report
