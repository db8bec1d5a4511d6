#pragma once
// SIGINT and SIGTERM end a command at its next safe point (between steps, between chart
// points) instead of killing it mid-write. A second signal kills at once, as usual.

#include <exception>
#include <string>

#include "kinema/adaptive.hpp"
#include "kinema/error.hpp"

namespace kinema::cli {

// Installs the handlers; call once at start.
void catch_interrupts();

// The signal received (SIGINT, SIGTERM), or 0.
int interrupting_signal();

// "SIGINT" or "SIGTERM".
std::string signal_name(int signal);

// Thrown at a safe point once a signal came; the program exits with 128 + signal.
struct Interrupted : std::exception {
  int signal;
  explicit Interrupted(int s) : signal(s) {}
  const char* what() const noexcept override { return "interrupted"; }
};

// Throws Interrupted when a signal came.
void stop_if_interrupted();

// A stop request for the library's long loops (World::advance, error control, the analyses):
// true once a signal came. It may be polled on any worker, inside a step; the analyses then
// throw kinema::Stopped, which the program reports as the signal (interrupted_by).
const StopRequest& interrupt_request();

// The signal a kinema::Stopped answered, or 0 (a stop the program did not ask for).
int interrupted_by(const Stopped& e);

// What a summary says of the error that ended a command: "stopped by SIGINT" for a stop that
// answered a signal, else e.what().
std::string error_text(const std::exception& e);

}  // namespace kinema::cli
