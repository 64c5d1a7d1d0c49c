// Grass: Hegeman Eq. 9 with a floor, or the field's blade layer (grass.h).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "canopy_ao/grass.h"

using namespace canopy_ao;

TEST(Grass, LawValues) {
  GrassOptions o;
  o.ground_height = 1.0f;
  o.blade_height = 0.5f;
  o.floor = 0.05f;
  const float c45 = std::sqrt(0.5f);
  // Half way up, normal up: (0.25/1)(1+1) = 0.5.
  EXPECT_NEAR(grass_visibility({3, 4, 1.25f}, {0, 0, 1}, o), 0.5f, 1e-6f);
  // Tip, tilted 45°: (1 + cos θ)/2, the open-sky AO of a tilted plane.
  EXPECT_NEAR(grass_visibility({0, 0, 1.5f}, {c45, 0, c45}, o), 0.5f * (1 + c45), 1e-6f);
  // Above the blades: same as the tip (Pz clamped to h).
  EXPECT_NEAR(grass_visibility({0, 0, 9.0f}, {c45, 0, c45}, o), 0.5f * (1 + c45), 1e-6f);
  // Horizontal normal, quarter height: (0.125/1)(1 + 0) = 0.125.
  EXPECT_NEAR(grass_visibility({0, 0, 1.125f}, {1, 0, 0}, o), 0.125f, 1e-6f);
  // Roots and ground under the grass: the floor. Below ground too.
  EXPECT_FLOAT_EQ(grass_visibility({0, 0, 1.0f}, {0, 0, 1}, o), 0.05f);
  EXPECT_FLOAT_EQ(grass_visibility({0, 0, -3.0f}, {0, 0, 1}, o), 0.05f);
  // Facing straight down anywhere: (1 + cos θ) = 0 → floor.
  EXPECT_FLOAT_EQ(grass_visibility({0, 0, 1.4f}, {0, 0, -1}, o), 0.05f);
  // Zero normal: horizontal.
  EXPECT_NEAR(grass_visibility({0, 0, 1.25f}, {0, 0, 0}, o), 0.25f, 1e-6f);
  // Non-unit normals are normalised.
  EXPECT_NEAR(grass_visibility({0, 0, 1.25f}, {0, 0, 7}, o), 0.5f, 1e-6f);
}

TEST(Grass, OtherUpAxisAndArrays) {
  GrassOptions o;
  o.up = {0, 2, 0};  // normalised internally
  o.blade_height = 2.0f;
  o.floor = 0.0f;
  std::vector<float> p = {0, 1, 0, 5, 0.5f, 5, 0, 4, 0};
  std::vector<float> n = {0, 1, 0, 0, 1, 0, 1, 0, 0};
  std::vector<float> v(3);
  ao_grass({p.data(), 3}, {n.data(), 3}, o, v.data());
  EXPECT_NEAR(v[0], 0.5f, 1e-6f);
  EXPECT_NEAR(v[1], 0.25f, 1e-6f);
  EXPECT_NEAR(v[2], 0.5f, 1e-6f);
  for (float x : v) EXPECT_TRUE(std::isfinite(x) && x >= 0 && x <= 1);
}

TEST(Grass, BadOptionsThrow) {
  const Vec3 x{0, 0, 0}, n{0, 0, 1};
  GrassOptions o;
  o.blade_height = 0;
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
  o = {};
  o.up = {0, 0, 0};
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
  o = {};
  o.floor = 1.5f;
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
  o = {};
  o.ground_height = NAN;
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
}

TEST(Grass, TheBladeLayerIsReadBilinearly) {
  // A 2 × 3 layer: rows s = 0, 1; columns cos θ = −1, 0, 1.
  GrassOptions o;
  o.ground_height = 1.0f;
  o.blade_height = 2.0f;
  o.floor = 0.0f;
  o.layer = {0.0f, 0.1f, 0.2f,   // at the roots
             0.4f, 0.5f, 0.9f};  // at the tips
  o.layer_rows = 2;
  o.layer_cols = 3;
  EXPECT_NEAR(grass_visibility({0, 0, 1.0f}, {1, 0, 0}, o), 0.1f, 1e-6f);   // root, sideways
  EXPECT_NEAR(grass_visibility({0, 0, 3.0f}, {0, 0, 1}, o), 0.9f, 1e-6f);   // tip, up
  EXPECT_NEAR(grass_visibility({0, 0, 9.0f}, {0, 0, -1}, o), 0.4f, 1e-6f);  // above: the tip
  EXPECT_NEAR(grass_visibility({0, 0, -5.0f}, {0, 0, 1}, o), 0.2f, 1e-6f);  // below: the root
  // Half way up (s = 0.5), half way between sideways and up (cos θ = 0.5): the mean of the
  // four corners around it, 0.1, 0.2, 0.5, 0.9.
  const float c = 0.5f, s = std::sqrt(0.75f);
  EXPECT_NEAR(grass_visibility({0, 0, 2.0f}, {s, 0, c}, o), 0.425f, 1e-6f);
  // The floor still holds; the array form agrees with the one-point form.
  o.floor = 0.3f;
  EXPECT_FLOAT_EQ(grass_visibility({0, 0, 1.0f}, {1, 0, 0}, o), 0.3f);
  std::vector<float> p = {0, 0, 2.0f, 0, 0, 3.0f}, n = {s, 0, c, 0, 0, 1}, v(2);
  ao_grass({p.data(), 2}, {n.data(), 2}, o, v.data());
  EXPECT_NEAR(v[0], 0.425f, 1e-6f);
  EXPECT_NEAR(v[1], 0.9f, 1e-6f);
}

TEST(Grass, ABadBladeLayerThrows) {
  const Vec3 x{0, 0, 0}, n{0, 0, 1};
  GrassOptions o;
  o.layer = {0.5f, 0.5f, 0.5f};
  o.layer_rows = 2;
  o.layer_cols = 2;  // 3 values for 2 × 2
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
  o.layer = {0.5f, 0.5f};
  o.layer_rows = 1;  // one row: nothing to interpolate
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
  o.layer = {0.5f, 0.5f, 0.5f, 1.5f};
  o.layer_rows = 2;
  o.layer_cols = 2;  // a value outside [0, 1]
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
  o.layer[3] = NAN;
  EXPECT_THROW(grass_visibility(x, n, o), std::invalid_argument);
}
