// The niceness of processing threads: recording runs at the daemon's own priority, processing
// below it, so that a busy pipeline never starves the thread that writes raw frames to disk.
#pragma once

#include <tbb/task_arena.h>
#include <tbb/task_scheduler_observer.h>

#include <atomic>

namespace plenopiv::daemon {

// Sets the calling thread's niceness (Linux keeps one per thread) to `nice` if it is below it;
// never raises a thread's priority (that needs CAP_SYS_NICE), so a thread already nicer keeps its
// value. `nice` in [0, 19]; 0 changes nothing. A refusal by the kernel throws std::system_error.
void lower_this_thread_priority(int nice);

// The calling thread's niceness.
int this_thread_niceness();

// Every thread that enters `arena` runs at `nice` from then on (lower_this_thread_priority); the
// thread that calls execute at `caller_nice` (default: `nice`). oneTBB's workers move between
// arenas; once niced they stay so (raising a priority needs CAP_SYS_NICE), which suits a daemon
// whose only TBB work is processing: workers run at one niceness whichever arena they serve.
class ArenaNiceness : public tbb::task_scheduler_observer {
 public:
  ArenaNiceness(tbb::task_arena& arena, int nice, int caller_nice = -1);
  ~ArenaNiceness() override;
  ArenaNiceness(const ArenaNiceness&) = delete;
  ArenaNiceness& operator=(const ArenaNiceness&) = delete;

  void on_scheduler_entry(bool is_worker) override;

 private:
  int nice_, caller_nice_;
  std::atomic<bool> warned_{false};
};

}  // namespace plenopiv::daemon
