#pragma once
// The names kinema_bench gives its runs (see the suites' register_all()), in one place.
#include <string>

namespace kinema::bench::report {

// The built-in fixed-step methods the particle suites run, in the tables' order.
inline const char* const kMethods[] = {"euler", "midpoint", "heun", "rk4", "symplectic_euler", "velocity_verlet"};

// fused/, ceiling/ and staged/ particle runs: kind/method/precision/isa/threads:t/n.
inline std::string kernel_run(const std::string& kind, const std::string& method, const std::string& p,
                              const std::string& isa, int threads, long n) {
  return kind + "/" + method + "/" + p + "/" + isa + "/threads:" + std::to_string(threads) + "/" +
         std::to_string(n) + "/real_time";
}

// naive_aos and odeint.
inline std::string baseline_run(const char* name, const std::string& p, long n) {
  return std::string(name) + "/rk4/" + p + "/" + std::to_string(n) + "/real_time";
}

// x += h v over n bodies' worth of floats.
inline std::string stream_run(long n, int threads) {
  return "limit/stream/" + std::to_string(n) + "/real_time/threads:" + std::to_string(threads);
}

// The particle state's own traffic at n bodies (7 arrays read, 6 written), widest ISA, with
// each array asked for `ahead` bytes ahead (0: not at all).
inline std::string state_stream_run(const std::string& p, long n, long ahead, int threads) {
  return "limit/state_stream/" + p + "/" + std::to_string(n) + "/" + std::to_string(ahead) +
         "/real_time/threads:" + std::to_string(threads);
}

inline std::string peak_run(const std::string& p, int threads) {
  return "limit/fma_peak/" + p + "/real_time/threads:" + std::to_string(threads);
}

inline std::string nbody_run(const std::string& p, const std::string& isa, int threads, long n) {
  return "nbody/" + p + "/" + isa + "/threads:" + std::to_string(threads) + "/" + std::to_string(n) + "/real_time";
}

// rigid/ and rigid-ceiling/ runs, all at 100000 bodies.
inline std::string rigid_run(const std::string& kind, const std::string& p, const std::string& isa, int threads) {
  return kind + "/rk4/" + p + "/" + isa + "/threads:" + std::to_string(threads) + "/100000/real_time";
}

// The paired 2-thread scaling at n bodies.
inline std::string scaling_run(const std::string& p, const std::string& isa) {
  return "scaling/rk4/" + p + "/" + isa + "/100000";
}

// A frame-loop row: back to back (gap 0) one run per variant, with gaps interleaved runs of a
// fixed number of rounds (kinema's variants in one, the peer in another).
inline std::string frame_loop_run(const std::string& p, int gap, const char* variant, long n) {
  const std::string size = std::to_string(n);
  if (gap == 0) return "frame_loop/" + p + "/gap_us:0/" + variant + "/" + size + "/manual_time";
  const std::string rounds = gap >= 8000 ? "12" : "30";  // bench/frame_loop.cpp
  // The peer takes turns with one thread in a row of its own (bench/frame_loop.cpp says why).
  const std::string row = std::string(variant) == "parallel_for" ? "/peer/" : "/interleaved/";
  return "frame_loop/" + p + "/gap_us:" + std::to_string(gap) + row + size + "/iterations:" + rounds + "/manual_time";
}

}  // namespace kinema::bench::report
