#include "artisan/core/scheduling.hpp"

#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include "artisan/core/error.hpp"

namespace artisan {

void run_in_background() {
  // Both calls act on the calling thread alone (Linux: policy and nice value are per thread).
  // Neither can fail for a thread lowering itself, so failures are ignored.
  sched_param param{};
  sched_setscheduler(0, SCHED_OTHER, &param);
  setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 10);
}

void run_in_realtime(int priority) {
  if (priority < 1 || priority > 99) throw Error("real-time priority " + std::to_string(priority) + " is outside 1 to 99");
  const auto refused = [](const std::string& what, const std::string& needs) {
    return Error("cannot " + what + " (" + std::strerror(errno) + "): it needs root, or " + needs);
  };
  // MCL_ONFAULT: pages are locked as they are touched, not all mapped memory up front.
  if (mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) != 0)
    throw refused("lock the process's memory", "the CAP_IPC_LOCK capability or a large enough memlock limit (ulimit -l)");
  sched_param param{};
  param.sched_priority = priority;
  if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) {
    const auto error = refused("run under SCHED_FIFO at priority " + std::to_string(priority),
                               "the CAP_SYS_NICE capability or an rtprio limit of at least that (ulimit -r)");
    munlockall();
    throw error;
  }
}

}  // namespace artisan
