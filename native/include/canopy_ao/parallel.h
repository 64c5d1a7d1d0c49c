// Canopy AO — deterministic parallel loops over points.
//
// Every per-point computation in the library goes through parallel_for_blocks: fixed-size
// blocks, each point computed independently of which thread runs it, so results never depend
// on the thread count. The thread count can be capped for benchmarks (set_max_threads).
#pragma once

#include <cstddef>
#include <functional>

namespace canopy_ao {

/// Caps worker threads for subsequent calls (0 = all cores). Returns the previous cap.
int set_max_threads(int n);
/// Worker threads calls will use now.
int max_threads();

/// Calls body(begin, end) on disjoint ranges covering [0, n), in parallel. Ranges are
/// multiples of `grain` (except the last). `body` must only write to its own range.
void parallel_for_blocks(std::size_t n, std::size_t grain,
                         const std::function<void(std::size_t, std::size_t)>& body);

}  // namespace canopy_ao
