// The niceness of processing threads (thread_priority.hpp).
#include "daemon/thread_priority.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <string>
#include <system_error>

#include <spdlog/spdlog.h>

namespace plenopiv::daemon {

int this_thread_niceness() {
  errno = 0;
  const int n = getpriority(PRIO_PROCESS, id_t(gettid()));
  if (n == -1 && errno != 0) throw std::system_error(errno, std::generic_category(), "getpriority");
  return n;
}

void lower_this_thread_priority(int nice) {
  if (nice <= 0 || this_thread_niceness() >= nice) return;
  if (setpriority(PRIO_PROCESS, id_t(gettid()), nice) != 0) {
    throw std::system_error(errno, std::generic_category(), "setpriority(" + std::to_string(nice) + ")");
  }
}

ArenaNiceness::ArenaNiceness(tbb::task_arena& arena, int nice, int caller_nice)
    : tbb::task_scheduler_observer(arena), nice_(nice), caller_nice_(caller_nice < 0 ? nice : caller_nice) {
  if (nice_ > 0 || caller_nice_ > 0) observe(true);
}

ArenaNiceness::~ArenaNiceness() { observe(false); }

// Called on the entering thread before it runs the arena's first task, where an exception would
// reach no one: a refusal (Linux lets any thread lower its own priority; a seccomp or LSM policy
// might not) is logged once and the thread works on at its old priority.
void ArenaNiceness::on_scheduler_entry(bool is_worker) {
  try {
    lower_this_thread_priority(is_worker ? nice_ : caller_nice_);
  } catch (const std::system_error& e) {
    if (!warned_.exchange(true)) {
      spdlog::warn("processing_nice: a processing thread keeps the recording's priority: {}", e.what());
    }
  }
}

}  // namespace plenopiv::daemon
