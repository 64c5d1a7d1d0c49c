// Canopy AO — seconds per native stage, for profiling a bake (bench/stage_profile.py).
//
// Off by default, and then each timed section costs one relaxed atomic load. On, a section adds
// its seconds to a process-wide total per stage name: StageTimer's wall seconds on the calling
// thread (which may wait for parallel work: a BVH build), or sums of thread CPU seconds over
// the worker threads of a parallel stage (names ending in "(CPU)"), which count only the time
// those threads ran, so a stage's share of the work holds whatever the thread count and the
// machine's load. Results never depend on whether profiling is on.
#pragma once

#include <chrono>
#include <string>
#include <utility>
#include <vector>

namespace canopy_ao {

/// Turns stage timing on or off (process-wide). Returns the previous state.
bool set_stage_profiling(bool on);
/// Whether stage timing is on.
bool stage_profiling();
/// Adds `seconds` to stage `name`'s total (thread-safe; a no-op while profiling is off).
void add_stage_seconds(const char* name, double seconds);
/// Every stage's total seconds and number of sections, in the order first seen; clears them.
std::vector<std::pair<std::string, std::pair<double, long long>>> take_stage_seconds();

/// This thread's CPU seconds so far (POSIX CLOCK_THREAD_CPUTIME_ID; elsewhere the steady
/// clock): a parallel stage summed over its worker threads counts only the time they ran, so
/// it stays meaningful on a machine shared with other jobs.
double thread_cpu_seconds();

/// Times one section: from construction to stop() (or destruction) into stage `name`.
/// `name` must outlive the timer (a string literal).
class StageTimer {
 public:
  explicit StageTimer(const char* name)
      : name_(stage_profiling() ? name : nullptr),
        start_(name_ ? std::chrono::steady_clock::now() : std::chrono::steady_clock::time_point{}) {}
  ~StageTimer() { stop(); }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;
  void stop() {
    if (!name_) return;
    add_stage_seconds(name_, std::chrono::duration<double>(std::chrono::steady_clock::now() -
                                                           start_).count());
    name_ = nullptr;
  }

 private:
  const char* name_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace canopy_ao
