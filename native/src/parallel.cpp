#include "canopy_ao/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <vector>

namespace canopy_ao {
namespace {
std::atomic<int> g_max_threads{0};

// One arena per thread count, created on first use and kept (deliberately never destroyed, so
// no arena is torn down during static destruction after TBB's own). A fresh arena per call
// costs its initialisation and the workers' migration into it on every call (tens of µs,
// visible at 10^5 points).
tbb::task_arena& arena_for(int threads) {
  static std::mutex mutex;
  static auto* arenas = new std::vector<std::unique_ptr<tbb::task_arena>>();
  std::lock_guard<std::mutex> lock(mutex);
  const std::size_t k = static_cast<std::size_t>(threads);
  if (arenas->size() <= k) arenas->resize(k + 1);
  auto& a = (*arenas)[k];
  if (!a) a = std::make_unique<tbb::task_arena>(threads);
  return *a;
}
}

int set_max_threads(int n) { return g_max_threads.exchange(n < 0 ? 0 : n); }

int max_threads() {
  const int cap = g_max_threads.load();
  const int all = tbb::info::default_concurrency();
  return cap > 0 && cap < all ? cap : all;
}

void parallel_for_blocks(std::size_t n, std::size_t grain,
                         const std::function<void(std::size_t, std::size_t)>& body) {
  if (n == 0) return;
  if (grain == 0) grain = 1;
  const int threads = max_threads();
  if (threads <= 1 || n <= grain) {
    body(0, n);
    return;
  }
  const std::size_t blocks = (n + grain - 1) / grain;
  // An arena of our own honours the cap without touching TBB's global state, so a cap set for a
  // benchmark cannot leak into Blender's own use of TBB.
  arena_for(threads).execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        const std::size_t b = r.begin() * grain;
                        const std::size_t e = std::min(n, r.end() * grain);
                        body(b, e);
                      });
  });
}

}  // namespace canopy_ao
