#pragma once
// Which core a thread runs on, and moving it off one: what TbbJobSystem's workers do when
// they find themselves on the core of the thread that posted their job.

namespace kinema::detail {

// The core the calling thread runs on now; -1 where the system does not say.
int current_cpu();

// Moves the calling thread off core `cpu`: its allowed cores without that one, then the mask
// it had again, so that it stays where it was moved. True when it was moved. Nothing happens
// (false) where that core is not allowed or is the only one, or where the system refuses.
// The mask put back is the one read before: a core a cpuset adds in between is not in it.
bool leave_core(int cpu);

}  // namespace kinema::detail
