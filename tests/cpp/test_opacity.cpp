// Canopy AO — the ray tracer's opacity (raytrace.h, "Opacity"): a card of alpha a over a receiver
// blocks a times what it blocks opaque; a texture's alpha is read at the hit's UV; the answer does
// not depend on the thread count; a tracer whose triangles are all opaque is the plain one.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"

using namespace canopy_ao;

namespace {

/// A horizontal square card (two triangles) of half-size s at height h over the origin, its UVs
/// spanning [0, 1]² (u along x, v along y).
struct Card {
  std::vector<float> v;
  std::vector<std::int32_t> t = {0, 1, 2, 0, 2, 3};
  std::vector<float> uv = {0, 0, 1, 0, 1, 1, 0, 0, 1, 1, 0, 1};
  Card(float s, float h) : v{-s, -s, h, s, -s, h, s, s, h, -s, s, h} {}
  PointsView view() const { return {v.data(), v.size() / 3}; }
  RayTracer tracer(const std::vector<AlphaMaterial>& alphas, std::int32_t material = 0) const {
    Opacity o;
    const std::vector<std::int32_t> mats(2, material);
    o.materials = mats.data();
    o.uvs = uv.data();
    o.alphas = alphas;
    return RayTracer(view(), t.data(), 2, BakeShading{}, o, {}, {});
  }
};

/// `count` receivers at `p` facing +z (each row its own rays).
struct Points {
  std::vector<float> p, n;
  Points(Vec3 at, std::size_t count) {
    for (std::size_t i = 0; i < count; ++i) {
      p.insert(p.end(), {at.x, at.y, at.z});
      n.insert(n.end(), {0.0f, 0.0f, 1.0f});
    }
  }
  PointsView points() const { return {p.data(), p.size() / 3}; }
  PointsView normals() const { return {n.data(), n.size() / 3}; }
};

double mean(const std::vector<float>& a) {
  return std::accumulate(a.begin(), a.end(), 0.0) / static_cast<double>(a.size());
}

RayTraceOptions opts(int samples) {
  RayTraceOptions o;
  o.samples = samples;
  return o;
}

AlphaMaterial constant(float a) {
  AlphaMaterial m;
  m.alpha = a;
  return m;
}

}  // namespace

TEST(Opacity, AUniformCardOfAlphaABlocksATimesItsOpaqueShare) {
  const Card card(1.0f, 1.0f);
  const Points r({0, 0, 0}, 64);
  const RayTracer plain(card.view(), card.t.data(), 2);
  const double blocked = 1.0 - mean(plain.ao(r.points(), r.normals(), opts(1024)));
  ASSERT_GT(blocked, 0.3);  // the card covers a good share of the sky
  for (float a : {0.0f, 0.25f, 0.5f, 1.0f}) {
    const RayTracer tracer = card.tracer({constant(a)});
    const double ao = mean(tracer.ao(r.points(), r.normals(), opts(1024)));
    // 65,536 rays: the hash's noise on the mean is below 0.002.
    EXPECT_NEAR(ao, 1.0 - a * blocked, 0.01) << "alpha " << a;
  }
  // alpha 0 never stops a ray, alpha 1 always does: exactly open, and exactly the plain tracer.
  for (float v : card.tracer({constant(0.0f)}).ao(r.points(), r.normals(), opts(64))) {
    EXPECT_EQ(v, 1.0f);
  }
  EXPECT_EQ(card.tracer({constant(1.0f)}).ao(r.points(), r.normals(), opts(64)),
            plain.ao(r.points(), r.normals(), opts(64)));
}

TEST(Opacity, ATexturedCardIsReadAtTheHitsUv) {
  // A 200 × 200 card at height 1 whose texture is opaque for u < ½ (x < 0), clear beyond.
  const Card card(100.0f, 1.0f);
  std::vector<float> texels(64 * 4, 0.0f);
  for (int row = 0; row < 4; ++row) {
    for (int col = 0; col < 32; ++col) texels[64 * row + col] = 1.0f;
  }
  AlphaMaterial m;
  m.texture = texels.data();
  m.width = 64;
  m.height = 4;
  const RayTracer tracer = card.tracer({m});
  EXPECT_TRUE(tracer.has_opacity());
  // Under the opaque half nearly every ray is stopped; under the clear half nearly none (only
  // rays grazing far enough to reach the opaque half, (1/50)² of the cosine-weighted sky).
  const Points under_opaque({-50, 0, 0}, 16), under_clear({50, 0, 0}, 16);
  EXPECT_LT(mean(tracer.ao(under_opaque.points(), under_opaque.normals(), opts(256))), 0.01);
  EXPECT_GT(mean(tracer.ao(under_clear.points(), under_clear.normals(), opts(256))), 0.99);
  // Under the edge, half the sky's card is opaque: AO about ½ (the texture's bilinear ramp
  // is 200 / 64 units wide there, symmetric about the edge).
  const Points under_edge({0, 0, 0}, 64);
  EXPECT_NEAR(mean(tracer.ao(under_edge.points(), under_edge.normals(), opts(1024))), 0.5,
              0.01);
}

TEST(Opacity, SameAnswerWhateverTheThreadCount) {
  const Card card(1.0f, 0.5f);
  const Points r({0.1f, -0.2f, 0}, 512);
  const RayTracer tracer = card.tracer({constant(0.5f)});
  const int prev = set_max_threads(1);
  const auto one = tracer.ao(r.points(), r.normals(), opts(64));
  set_max_threads(2);
  const auto two = tracer.ao(r.points(), r.normals(), opts(64));
  set_max_threads(0);
  const auto all = tracer.ao(r.points(), r.normals(), opts(64));
  set_max_threads(prev);
  EXPECT_EQ(one, two);
  EXPECT_EQ(one, all);
}

TEST(Opacity, AllOpaqueIsThePlainTracer) {
  const Card card(1.0f, 1.0f);
  EXPECT_FALSE(card.tracer({constant(1.0f)}).has_opacity());
  EXPECT_FALSE(card.tracer({constant(0.5f)}, -1).has_opacity());  // no triangle uses it
  EXPECT_TRUE(card.tracer({constant(0.5f)}).has_opacity());
}

TEST(Opacity, BadOpacityThrowsInvalidArgument) {
  const Card card(1.0f, 1.0f);
  EXPECT_THROW(card.tracer({constant(0.5f)}, 1), std::invalid_argument);   // no material 1
  EXPECT_THROW(card.tracer({constant(0.5f)}, -2), std::invalid_argument);
  EXPECT_THROW(card.tracer({constant(std::numeric_limits<float>::quiet_NaN())}),
               std::invalid_argument);
  AlphaMaterial empty;
  std::vector<float> one(1, 0.5f);
  empty.texture = one.data();  // a texture of no size
  EXPECT_THROW(card.tracer({empty}), std::invalid_argument);
}

TEST(Opacity, ATexturesValueIsDecodedFromSrgbAfterInterpolationThenScaled) {
  // A uniform texel of 0.5 encoded: alpha = offset + scale · decode(0.5) = 1 − 0.214 (inverted).
  const Card card(1.0f, 1.0f);
  const Points r({0, 0, 0}, 64);
  const RayTracer plain(card.view(), card.t.data(), 2);
  const double blocked = 1.0 - mean(plain.ao(r.points(), r.normals(), opts(1024)));
  std::vector<float> texels(4, 0.5f);
  AlphaMaterial m;
  m.texture = texels.data();
  m.width = m.height = 2;
  m.srgb = true;
  m.scale = -1.0f;
  m.offset = 1.0f;
  const double alpha = 1.0 - 0.21404114;  // Cycles' color_srgb_to_linear(0.5)
  EXPECT_NEAR(mean(card.tracer({m}).ao(r.points(), r.normals(), opts(1024))),
              1.0 - alpha * blocked, 0.01);
}

TEST(Opacity, ClosestReadsTheTexelTheUvFallsIn) {
  // Two texels, opaque then clear, on a 200 × 200 card at height 1. Under x = -90 (u = 0.05)
  // the nearest texel is the opaque one; Linear blends in the clear one across the wrap.
  const Card card(100.0f, 1.0f);
  std::vector<float> texels = {1.0f, 0.0f};
  AlphaMaterial m;
  m.texture = texels.data();
  m.width = 2;
  m.height = 1;
  const Points r({-90, 0, 0}, 16);
  const double linear = mean(card.tracer({m}).ao(r.points(), r.normals(), opts(256)));
  m.nearest = true;
  const double nearest = mean(card.tracer({m}).ao(r.points(), r.normals(), opts(256)));
  EXPECT_LT(nearest, 0.05);  // only rays past the card's edge, 10 units away at height 1
  EXPECT_GT(linear, 0.2);
}
