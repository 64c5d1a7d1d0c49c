#include <gtest/gtest.h>

#include <vector>

#include "canopy_ao/parallel.h"

using namespace canopy_ao;

TEST(Parallel, CoversEveryIndexOnceWhateverTheThreadCount) {
  for (int threads : {1, 2, 0}) {
    const int prev = set_max_threads(threads);
    std::vector<int> hits(10007, 0);
    parallel_for_blocks(hits.size(), 64, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) hits[i] += 1;
    });
    for (int h : hits) ASSERT_EQ(h, 1);
    set_max_threads(prev);
  }
}

TEST(Parallel, EmptyRangeCallsNothing) {
  bool called = false;
  parallel_for_blocks(0, 16, [&](std::size_t, std::size_t) { called = true; });
  EXPECT_FALSE(called);
}
