#pragma once
// How a thread competes for the CPU. A service that answers clients within milliseconds runs
// its serving thread in real time (its memory locked, so no page of it is evicted and read back
// in the middle of an answer), and its long jobs (re-cutting an environment, freeing what it
// replaced, copying a database's log) in the background, below anything that serves.

namespace artisan {

/// The calling thread from now on: ordinary time-sharing (SCHED_OTHER) at nice 10, also when it
/// was started by a real-time thread, whose policy it inherited.
void run_in_background();

/// The calling thread from now on: SCHED_FIFO at `priority` (1 to 99), preempting every ordinary
/// thread on the machine, the kernel's own included (e.g. a memory monitor that takes a CPU for
/// tens of milliseconds); and the process's pages are locked in RAM as they are touched.
/// Throws artisan::Error saying what the system refused and what it needs (root, or the
/// CAP_SYS_NICE and CAP_IPC_LOCK capabilities, or rtprio and memlock limits).
void run_in_realtime(int priority);

}  // namespace artisan
