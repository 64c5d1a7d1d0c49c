// Opaque convex patches as occluders (patches.h): known form factors, the AO distance's disc,
// a receiver on the patch's own plane, and results independent of the thread count.
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <random>
#include <vector>

#include "canopy_ao/parallel.h"
#include "canopy_ao/patches.h"

using namespace canopy_ao;

namespace {

/// An axis-aligned square of half side `a` in the plane z = `z`, facing −z (towards a receiver
/// below it), corners counter-clockwise about its normal.
PatchPolygon square(double a, double z) {
  PatchPolygon p;
  p.corners = {-a, -a, z, -a, a, z, a, a, z, a, -a, z};
  p.normal[0] = 0;
  p.normal[1] = 0;
  p.normal[2] = -1;
  p.offset = -z;
  p.diameter = std::sqrt(8.0) * a;
  return p;
}

float visibility(const std::vector<PatchPolygon>& patches, std::vector<double> p,
                 std::vector<double> n, double distance = INFINITY, double near = 0.0) {
  float out = -1;
  patch_visibility(patches, p.data(), n.data(), 1, distance, near, &out);
  return out;
}

// The form factor from a point to a parallel a × b rectangle at height h above one corner.
double corner_rectangle(double a, double b, double h) {
  const double A = a / h, B = b / h, pi = 3.14159265358979323846;
  return (A / std::sqrt(1 + A * A) * std::atan(B / std::sqrt(1 + A * A)) +
          B / std::sqrt(1 + B * B) * std::atan(A / std::sqrt(1 + B * B))) /
         (2 * pi);
}

}  // namespace

TEST(Patches, SquareAboveTheReceiverHasItsKnownFormFactor) {
  // Under the centre of a 2 × 2 square at height 1: four corner rectangles of 1 × 1.
  const double want = 4 * corner_rectangle(1, 1, 1);
  EXPECT_NEAR(visibility({square(1, 1)}, {0, 0, 0}, {0, 0, 1}), 1 - want, 1e-6);
  // Facing away, the square is below the horizon; no normal, no occlusion.
  EXPECT_EQ(visibility({square(1, 1)}, {0, 0, 0}, {0, 0, -1}), 1.0f);
  EXPECT_EQ(visibility({square(1, 1)}, {0, 0, 0}, {0, 0, 0}), 1.0f);
}

TEST(Patches, SidewaysReceiverSeesHalfOfABigPlane) {
  // A receiver facing +x just under a huge plane: the plane fills the upper half of its
  // hemisphere, form factor 1/2.
  EXPECT_NEAR(visibility({square(1e6, 1)}, {0, 0, 0}, {1, 0, 0}), 0.5, 1e-4);
}

TEST(Patches, TheAoDistanceCutsThePlaneToItsDisc) {
  // A big plane at height 1, distance 2: the disc of radius sqrt(3), form factor
  // r² / (r² + h²) = 3/4 (the disc as an octagon of its area: within 2e-3).
  const std::vector<PatchPolygon> big{square(1e3, 1)};
  EXPECT_NEAR(visibility(big, {0, 0, 0}, {0, 0, 1}, 2.0), 0.25, 2e-3);
  // Between near = 1.25 and D = 2: the two discs' form factors' difference.
  EXPECT_NEAR(visibility(big, {0, 0, 0}, {0, 0, 1}, 2.0, 1.25),
              1 - (0.75 - (1 - 1 / (1.25 * 1.25))), 2e-3);
  // Out of reach.
  EXPECT_EQ(visibility(big, {0, 0, 0}, {0, 0, 1}, 0.5), 1.0f);
}

TEST(Patches, AReceiverOnThePlaneSeesItEdgeOn) {
  // On the patch's own plane (its back side is where the receiver faces): no occlusion.
  PatchPolygon ground = square(5, 0);
  ground.normal[2] = 1;  // facing up
  ground.offset = 0;
  EXPECT_NEAR(visibility({ground}, {0.3, 0.2, 0}, {0, 0, 1}), 1.0, 1e-5);
  // Facing sideways on it: the plane fills half its hemisphere.
  EXPECT_NEAR(visibility({ground}, {0.3, 0.2, 0}, {1, 0, 0}), 0.5, 2e-3);
}

TEST(Patches, SumsAreClippedToZero) {
  // Two copies of a big plane cover more than the hemisphere: V clipped to 0, never below.
  EXPECT_EQ(visibility({square(1e3, 1), square(1e3, 1)}, {0, 0, 0}, {0, 0, 1}), 0.0f);
}

TEST(Patches, ResultsDoNotDependOnTheThreadCount) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  const std::size_t n = 5000;
  std::vector<double> p(3 * n), q(3 * n);
  for (auto& v : p) v = 2 * g(rng);
  for (auto& v : q) v = g(rng);
  const std::vector<PatchPolygon> patches{square(1, 1), square(3, -0.5)};
  std::vector<float> one(n), all(n);
  const int before = set_max_threads(1);
  patch_visibility(patches, p.data(), q.data(), n, 4.0, 0.5, one.data());
  set_max_threads(0);
  patch_visibility(patches, p.data(), q.data(), n, 4.0, 0.5, all.data());
  set_max_threads(before);
  EXPECT_EQ(one, all);
  bool some = false;
  for (float v : one) {
    EXPECT_TRUE(v >= 0.0f && v <= 1.0f);
    some = some || v < 0.9f;
  }
  EXPECT_TRUE(some);  // the receivers do see the patches
}
