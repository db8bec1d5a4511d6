#include "interrupt.hpp"

#include <atomic>
#include <csignal>

namespace kinema::cli {
namespace {

// Read by workers inside a step as well as by the main thread: a lock-free atomic, which a
// handler may write.
std::atomic<int> received{0};
static_assert(std::atomic<int>::is_always_lock_free);

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
  static const StopRequest request = [] { return received != 0; };
  return request;
}

int interrupted_by(const Stopped&) { return received; }

std::string error_text(const std::exception& e) {
  const bool stop = dynamic_cast<const Stopped*>(&e) != nullptr || dynamic_cast<const Interrupted*>(&e) != nullptr;
  return stop && received != 0 ? "stopped by " + signal_name(received) : e.what();
}

}  // namespace kinema::cli
