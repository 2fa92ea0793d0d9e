// Thread scheduling: background threads below the serving thread, whatever they inherited; the
// serving thread in real time when the system allows it, and a clear refusal when it does not.
#include <gtest/gtest.h>
#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <string>
#include <thread>

#include "artisan/core/error.hpp"
#include "artisan/core/scheduling.hpp"

namespace artisan {
namespace {

int own_nice() { return getpriority(PRIO_PROCESS, static_cast<id_t>(::gettid())); }

// Whether this process may use SCHED_FIFO: probed on a thread of its own.
bool realtime_allowed() {
  bool allowed = false;
  std::thread([&] {
    sched_param p{};
    p.sched_priority = 1;
    allowed = sched_setscheduler(0, SCHED_FIFO, &p) == 0;
  }).join();
  return allowed;
}

TEST(Scheduling, ABackgroundThreadIsNiceTenAndTimeShared) {
  int policy = -1, nice = 0, main_nice = own_nice();
  std::thread([&] {
    run_in_background();
    policy = sched_getscheduler(0);
    nice = own_nice();
  }).join();
  EXPECT_EQ(policy, SCHED_OTHER);
  EXPECT_EQ(nice, 10);
  EXPECT_EQ(own_nice(), main_nice) << "only the calling thread changes";
}

TEST(Scheduling, ARealTimeThreadIsFifoAndItsBackgroundThreadsAreNot) {
  EXPECT_THROW(run_in_realtime(0), Error);
  EXPECT_THROW(run_in_realtime(100), Error);
  const bool allowed = realtime_allowed();
  int policy = -1, priority = -1, child_policy = -1, child_nice = 0;
  std::string refusal;
  std::thread([&] {
    try {
      run_in_realtime(20);
    } catch (const Error& e) {
      refusal = e.what();
      return;
    }
    policy = sched_getscheduler(0);
    sched_param p{};
    sched_getparam(0, &p);
    priority = p.sched_priority;
    // A thread started from here inherits SCHED_FIFO until it steps down.
    std::thread([&] {
      run_in_background();
      child_policy = sched_getscheduler(0);
      child_nice = own_nice();
    }).join();
    run_in_background();
  }).join();
  if (allowed) {
    EXPECT_EQ(refusal, "");
    EXPECT_EQ(policy, SCHED_FIFO);
    EXPECT_EQ(priority, 20);
    EXPECT_EQ(child_policy, SCHED_OTHER);
    EXPECT_EQ(child_nice, 10);
  } else {
    EXPECT_NE(refusal.find("needs root"), std::string::npos) << refusal;
  }
}

}  // namespace
}  // namespace artisan
