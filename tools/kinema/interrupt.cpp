#include "interrupt.hpp"

#include <csignal>

namespace kinema::cli {
namespace {

volatile std::sig_atomic_t received = 0;

extern "C" void note_signal(int signal) { received = signal; }

}  // namespace

void catch_interrupts() {
  struct sigaction action {};
  action.sa_handler = note_signal;
  sigemptyset(&action.sa_mask);
  // SA_RESETHAND: the next signal takes the default action (a second Ctrl-C kills).
  // SA_RESTART: writes in progress complete instead of failing with EINTR.
  action.sa_flags = SA_RESETHAND | SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

int interrupting_signal() { return received; }

std::string signal_name(int signal) {
  return signal == SIGINT ? "SIGINT" : signal == SIGTERM ? "SIGTERM" : "signal " + std::to_string(signal);
}

void stop_if_interrupted() {
  if (received != 0) throw Interrupted(received);
}

const StopRequest& interrupt_request() {
  static const StopRequest request = [] {
    stop_if_interrupted();
    return false;
  };
  return request;
}

}  // namespace kinema::cli
