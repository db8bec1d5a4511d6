#pragma once
// SIGINT and SIGTERM end a command at its next safe point (between steps, between chart
// points) instead of killing it mid-write. A second signal kills at once, as usual.

#include <exception>
#include <string>

#include "kinema/adaptive.hpp"

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

// A stop request for the library's long loops (World::advance, the analyses): it throws
// Interrupted, between two of their calls, once a signal came.
const StopRequest& interrupt_request();

}  // namespace kinema::cli
