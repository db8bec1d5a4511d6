#pragma once
// The exception type of kinema: thrown at set-up, never from inside a step's kernels.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace kinema {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// A body with a value that is not finite, and its first such field: "px" .. "vz", for rigid
// bodies also "qw" .. "qz", "lx" .. "lz".
struct NonFinite {
  std::size_t body;
  const char* field;
};

// Thrown by a step under a finiteness guard (StepperOptions::guard) when its result is not
// finite. The bodies and the stepper's clock hold the state before that step.
class NonFiniteError : public Error {
 public:
  NonFiniteError(std::uint64_t step, double time, std::size_t body, std::string field);
  std::uint64_t step;  // of the advance call that threw, from 1
  double time;         // of the state kept (the start of that step)
  std::size_t body;    // the lowest-numbered body with a value that is not finite
  std::string field;   // its first such field: "px" .. "vz", rigid bodies also "qw" .. "lz"
};

// Thrown by an implicit method's step whose linear solve overflows the precision (its sums,
// or its right side from a finite state): the springs' stiffness times the step squared over
// the masses too large for T, or a state blowing up. The bodies and the clock hold the state
// before that step (under a finiteness guard, before the call). The charts count it as a
// blow-up, as a state that is not finite.
class SolveOverflowError : public Error {
 public:
  using Error::Error;
};

// Thrown by a long analysis (simulate, reference_states, choose_method, estimate_stiffness)
// when the stop request it was given returned true: it has no result to give. Not an Error:
// nothing was wrong with the input.
class Stopped : public std::exception {
 public:
  const char* what() const noexcept override { return "stopped on request"; }
};

// Polled by the long loops: true stops them. Stepper::advance_to polls one after each
// accepted step (the set at the last accepted step; for signals, frame budgets, checkpoints)
// and an interrupt inside attempts too; Stepper::advance inside steps of N-body gravity or
// user code; World::advance between its calls of a few milliseconds; the long analyses
// (kinema/accuracy.hpp, estimate_stiffness, the N-body potential) between their runs, force
// evaluations or millions of pairs, throwing Stopped.
using StopRequest = std::function<bool()>;

// `text` made safe for one line of a terminal or of a script's string literal: control
// characters (C0, DEL, C1) and bytes that are not valid UTF-8 become \xNN (C1 code points
// \u00NN); every other character, Unicode included, stays as it is. Past `limit` bytes of
// output the rest is left out and counted ("... (N more bytes)").
std::string printable(std::string_view text, std::size_t limit = std::string_view::npos);

}  // namespace kinema
