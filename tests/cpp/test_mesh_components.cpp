// Connected pieces of a mesh (mesh_components.h): known answers, and labels numbered in order
// of each piece's first vertex.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "canopy_ao/mesh_components.h"

using namespace canopy_ao;

TEST(MeshComponents, KnownAnswer) {
  // Two triangles sharing an edge, one lone triangle, one unused vertex.
  const std::vector<std::int32_t> t{0, 1, 2, 2, 1, 3, 4, 5, 6};
  EXPECT_EQ(connected_components(8, t.data(), 3),
            (std::vector<std::int64_t>{0, 0, 0, 0, 1, 1, 1, 2}));
}

TEST(MeshComponents, FirstVertexOrderWhateverTheTriangleOrder) {
  // Pieces {1, 5, 6}, {0, 3}, {2}, {4, 7}: the piece holding vertex 0 is label 0, and so on,
  // although the triangles name them in another order.
  const std::vector<std::int32_t> t{6, 5, 1, 7, 4, 4, 3, 0, 3};
  EXPECT_EQ(connected_components(8, t.data(), 3),
            (std::vector<std::int64_t>{0, 1, 2, 0, 3, 1, 1, 3}));
}

TEST(MeshComponents, LongChainIsOnePiece) {
  // A path named from its far end: the worst case for label propagation.
  const std::size_t n = 100000;
  std::vector<std::int32_t> t;
  for (std::size_t i = n - 2; i-- > 0;) {
    t.insert(t.end(), {static_cast<std::int32_t>(i + 2), static_cast<std::int32_t>(i + 1),
                       static_cast<std::int32_t>(i)});
  }
  const auto labels = connected_components(n, t.data(), t.size() / 3);
  for (std::int64_t l : labels) ASSERT_EQ(l, 0);
}

TEST(MeshComponents, EmptyMesh) {
  EXPECT_TRUE(connected_components(0, nullptr, 0).empty());
  EXPECT_EQ(connected_components(3, nullptr, 0), (std::vector<std::int64_t>{0, 1, 2}));
}
