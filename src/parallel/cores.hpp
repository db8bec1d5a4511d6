#pragma once
// Which core a thread runs on, and moving it off one: what TbbJobSystem's workers do when
// they find themselves on the core of the thread that posted their job.

namespace kinema::detail {

// The core the calling thread runs on now; -1 where the system does not say.
int current_cpu();

// Moves the calling thread off core `cpu`: its allowed cores without that one, then all of
// them again, so that it stays where it was moved. Nothing happens where that core is the
// only one allowed, or where the system refuses.
void leave_core(int cpu);

}  // namespace kinema::detail
