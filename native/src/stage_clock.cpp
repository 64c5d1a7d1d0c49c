#include "canopy_ao/stage_clock.h"

#include <time.h>

#include <atomic>
#include <chrono>
#include <mutex>

namespace canopy_ao {
namespace {
std::atomic<bool> g_on{false};
std::mutex g_mutex;
// Few stages (a dozen names): a vector searched by name keeps their first-seen order.
std::vector<std::pair<std::string, std::pair<double, long long>>> g_totals;
}  // namespace

double thread_cpu_seconds() {
#if defined(CLOCK_THREAD_CPUTIME_ID)
  timespec ts;
  if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts) == 0) {
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
#endif
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

bool set_stage_profiling(bool on) { return g_on.exchange(on); }

bool stage_profiling() { return g_on.load(std::memory_order_relaxed); }

void add_stage_seconds(const char* name, double seconds) {
  if (!stage_profiling()) return;
  std::lock_guard<std::mutex> lock(g_mutex);
  for (auto& t : g_totals) {
    if (t.first == name) {
      t.second.first += seconds;
      t.second.second += 1;
      return;
    }
  }
  g_totals.emplace_back(name, std::make_pair(seconds, 1LL));
}

std::vector<std::pair<std::string, std::pair<double, long long>>> take_stage_seconds() {
  std::lock_guard<std::mutex> lock(g_mutex);
  auto out = std::move(g_totals);
  g_totals.clear();
  return out;
}

}  // namespace canopy_ao
