// Per-texel raster, splat and margin: known answers, brute-force coverage, determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "canopy_ao/parallel.h"
#include "canopy_ao/texel_raster.h"

using namespace canopy_ao;

namespace {

// Triangles in per-corner arrays, with positions derived from UVs unless given.
struct Mesh {
  std::vector<float> uv, pos, nrm;
  void add(float u0, float v0, float u1, float v1, float u2, float v2) {
    const float u[3] = {u0, u1, u2}, v[3] = {v0, v1, v2};
    for (int k = 0; k < 3; ++k) {
      uv.insert(uv.end(), {u[k], v[k]});
      // An affine map of UV: interpolation must reproduce it exactly.
      pos.insert(pos.end(), {2 * u[k] + 1, 3 * v[k] - 1, u[k] + v[k]});
      nrm.insert(nrm.end(), {0, 0, 1});
    }
  }
  std::size_t count() const { return uv.size() / 6; }
  CornerTriangles view(bool with_normals = true) const {
    return {uv.data(), pos.data(), with_normals ? nrm.data() : nullptr, count()};
  }
};

TexelSet raster(const Mesh& m, int w, int h, bool conservative = true) {
  RasterOptions o;
  o.width = w;
  o.height = h;
  o.conservative = conservative;
  return rasterize_uv(m.view(), o);
}

std::set<int> exact_pixels(const TexelSet& t) {
  std::set<int> s;
  for (std::size_t n = 0; n < t.size(); ++n) {
    if (t.exact[n]) s.insert(t.pixels[n]);
  }
  return s;
}

// Signed distance (texels) of centre c from the line of edge a→b, in double on the unsnapped UVs.
double edge_distance(double ax, double ay, double bx, double by, double cx, double cy) {
  const double ex = bx - ax, ey = by - ay;
  return (ex * (cy - ay) - ey * (cx - ax)) / std::hypot(ex, ey);
}

}  // namespace

TEST(TexelRaster, SingleTriangleCoverageMatchesBruteForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(-0.1f, 1.1f);
  for (int trial = 0; trial < 200; ++trial) {
    const int W = trial % 2 ? 37 : 64, H = trial % 3 ? 29 : 64;
    Mesh m;
    m.add(U(rng), U(rng), U(rng), U(rng), U(rng), U(rng));
    const TexelSet t = raster(m, W, H);
    const std::set<int> got = exact_pixels(t);
    // Brute force over every texel centre; centres within 0.01 texel of an edge are ambiguous
    // after snapping to 1/256 texel, so they may go either way.
    double x[3], y[3];
    for (int k = 0; k < 3; ++k) x[k] = m.uv[2 * k] * W, y[k] = m.uv[2 * k + 1] * H;
    const double area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
    if (std::fabs(area) < 1e-3) continue;
    const double sign = area > 0 ? 1 : -1;
    std::size_t inside = 0, ambiguous = 0;
    for (int j = 0; j < H; ++j) {
      for (int i = 0; i < W; ++i) {
        double dmin = 1e30;
        for (int k = 0; k < 3; ++k) {
          const int a = (k + 1) % 3, b = (k + 2) % 3;
          dmin = std::min(dmin, sign * edge_distance(x[a], y[a], x[b], y[b], i + 0.5, j + 0.5));
        }
        const int p = j * W + i;
        if (std::fabs(dmin) < 0.01) {
          ++ambiguous;
        } else if (dmin > 0) {
          ++inside;
          EXPECT_TRUE(got.count(p)) << "trial " << trial << " missed texel " << i << "," << j;
        } else {
          EXPECT_FALSE(got.count(p)) << "trial " << trial << " extra texel " << i << "," << j;
        }
      }
    }
    EXPECT_GE(got.size(), inside);
    EXPECT_LE(got.size(), inside + ambiguous);
    EXPECT_EQ(t.stats.exact_texels, got.size());
    EXPECT_EQ(t.stats.overlapping_texels, 0u);
  }
}

TEST(TexelRaster, UvSquareCoversExactlyItsTexels) {
  Mesh m;  // [0.25, 0.75]² at 16² = texels 4..11 in each direction
  m.add(0.25f, 0.25f, 0.75f, 0.25f, 0.75f, 0.75f);
  m.add(0.25f, 0.25f, 0.75f, 0.75f, 0.25f, 0.75f);
  const TexelSet t = raster(m, 16, 16);
  std::set<int> want;
  for (int j = 4; j < 12; ++j)
    for (int i = 4; i < 12; ++i) want.insert(j * 16 + i);
  EXPECT_EQ(exact_pixels(t), want);
  EXPECT_EQ(t.size(), 64u);  // squares outside only meet the island on their border
  EXPECT_EQ(t.stats.conservative_texels, 0u);
  EXPECT_EQ(t.stats.overlapping_texels, 0u);
  EXPECT_TRUE(std::is_sorted(t.pixels.begin(), t.pixels.end()));
}

TEST(TexelRaster, SharedEdgeThroughCentresCoversEachTexelOnce) {
  // The diagonal (0,0)-(1,1) of an 8² image runs through the centres (i+½, i+½).
  for (bool flip : {false, true}) {
    Mesh m;
    m.add(0, 0, 1, 0, 1, 1);
    if (flip) m.add(0, 0, 0, 1, 1, 1);  // clockwise: mirrored island half
    else m.add(0, 0, 1, 1, 0, 1);
    const TexelSet t = raster(m, 8, 8);
    EXPECT_EQ(t.size(), 64u);
    EXPECT_EQ(t.stats.exact_texels, 64u);
    EXPECT_EQ(t.stats.overlapping_texels, 0u);
    for (std::size_t n = 0; n < t.size(); ++n) EXPECT_EQ(t.pixels[n], int(n));
  }
}

TEST(TexelRaster, FanVerticesOnTexelCentresAreCoveredOnce) {
  // A 10×10 grid whose vertices sit on texel centres, quads split along alternating diagonals:
  // every centre strictly inside the grid is a vertex or on an edge of several triangles, yet
  // is covered exactly once.
  const int W = 32, H = 32, N = 10, step = 2;
  Mesh m;
  auto c = [&](int i) { return (4 + step * i + 0.5f) / W; };
  for (int b = 0; b < N; ++b) {
    for (int a = 0; a < N; ++a) {
      if ((a + b) % 2) {
        m.add(c(a), c(b), c(a + 1), c(b), c(a + 1), c(b + 1));
        m.add(c(a), c(b), c(a + 1), c(b + 1), c(a), c(b + 1));
      } else {
        m.add(c(a), c(b), c(a + 1), c(b), c(a), c(b + 1));
        m.add(c(a + 1), c(b), c(a + 1), c(b + 1), c(a), c(b + 1));
      }
    }
  }
  const TexelSet t = raster(m, W, H, false);
  EXPECT_EQ(t.stats.overlapping_texels, 0u);
  const std::set<int> got = exact_pixels(t);
  EXPECT_EQ(got.size(), t.size());
  for (int j = 5; j < 4 + step * N; ++j)
    for (int i = 5; i < 4 + step * N; ++i) EXPECT_TRUE(got.count(j * W + i)) << i << "," << j;
}

TEST(TexelRaster, OverlappingIslandsAreCounted) {
  Mesh m;
  m.add(0.1f, 0.1f, 0.9f, 0.1f, 0.5f, 0.9f);
  const std::size_t alone = raster(m, 32, 32).stats.exact_texels;
  m.add(0.1f, 0.1f, 0.5f, 0.9f, 0.9f, 0.1f);  // the same island again, mirrored
  const TexelSet t = raster(m, 32, 32);
  EXPECT_EQ(t.stats.exact_texels, alone);
  EXPECT_EQ(t.stats.overlapping_texels, alone);
  for (std::size_t n = 0; n < t.size(); ++n) {
    if (t.exact[n]) EXPECT_EQ(t.triangles[n], 0);  // the lower id wins
  }
}

TEST(TexelRaster, DegenerateAndInvalidTrianglesAreSkippedAndCounted) {
  Mesh m;
  m.add(0.1f, 0.1f, 0.5f, 0.5f, 0.9f, 0.9f);  // collinear
  m.add(0.2f, 0.2f, 0.2f, 0.2f, 0.2f, 0.2f);  // a point
  m.add(NAN, 0.1f, 0.5f, 0.5f, 0.9f, 0.1f);
  m.add(100.f, 0.1f, 0.5f, 0.5f, 0.9f, 0.1f);
  m.add(2.f, 2.f, 3.f, 2.f, 2.f, 3.f);  // valid but outside the 0..1 tile
  const TexelSet t = raster(m, 64, 64);
  EXPECT_EQ(t.size(), 0u);
  EXPECT_EQ(t.stats.degenerate, 2u);
  EXPECT_EQ(t.stats.invalid_uv, 2u);
  EXPECT_EQ(t.stats.triangles, 5u);
}

TEST(TexelRaster, InterpolationMatchesBarycentric) {
  // UVs on the 1/32 grid snap exactly, so interpolation must reproduce the affine map of UV.
  const int W = 32, H = 32;
  Mesh m;
  m.add(3.f / W, 2.f / H, 29.f / W, 7.f / H, 11.f / W, 30.f / H);
  const float n0[3] = {1, 0, 0}, n1[3] = {0, 1, 0}, n2[3] = {0, 0, 1};
  for (int k = 0; k < 3; ++k) m.nrm[k] = n0[k], m.nrm[3 + k] = n1[k], m.nrm[6 + k] = n2[k];
  const TexelSet t = raster(m, W, H);
  ASSERT_GT(t.stats.exact_texels, 100u);
  for (std::size_t n = 0; n < t.size(); ++n) {
    const float* b = &t.barycentrics[3 * n];
    EXPECT_NEAR(b[0] + b[1] + b[2], 1.0f, 1e-6f);
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(b[k], -1e-6f);
      EXPECT_LE(b[k], 1 + 1e-6f);
    }
    // Interpolated UV = this texel's centre when exact; a point of the triangle otherwise.
    const float u = b[0] * m.uv[0] + b[1] * m.uv[2] + b[2] * m.uv[4];
    const float v = b[0] * m.uv[1] + b[1] * m.uv[3] + b[2] * m.uv[5];
    const int i = t.pixels[n] % W, j = t.pixels[n] / W;
    if (t.exact[n]) {
      EXPECT_NEAR(u, (i + 0.5f) / W, 1e-6f);
      EXPECT_NEAR(v, (j + 0.5f) / H, 1e-6f);
    } else {
      // The nearest point of a triangle touching the texel's square: no farther from the
      // centre than the square's corners.
      EXPECT_LE(std::hypot(u * W - (i + 0.5f), v * H - (j + 0.5f)), std::sqrt(0.5f) + 1e-4f);
    }
    EXPECT_NEAR(t.positions[3 * n + 0], 2 * u + 1, 1e-5f);
    EXPECT_NEAR(t.positions[3 * n + 1], 3 * v - 1, 1e-5f);
    EXPECT_NEAR(t.positions[3 * n + 2], u + v, 1e-5f);
    const float len = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(t.normals[3 * n + k], b[k] / len, 1e-5f);
  }
}

TEST(TexelRaster, FaceNormalWhenNoNormalsGiven) {
  Mesh m;
  m.add(0.1f, 0.1f, 0.9f, 0.1f, 0.1f, 0.9f);
  RasterOptions o;
  o.width = o.height = 16;
  const TexelSet t = rasterize_uv(m.view(false), o);
  ASSERT_GT(t.size(), 0u);
  // positions (2u+1, 3v-1, u+v): face normal ∝ (2,0,1)×(0,3,1) = (-3,-2,6)/7.
  for (std::size_t n = 0; n < t.size(); ++n) {
    EXPECT_NEAR(t.normals[3 * n + 0], -3.f / 7, 1e-5f);
    EXPECT_NEAR(t.normals[3 * n + 1], -2.f / 7, 1e-5f);
    EXPECT_NEAR(t.normals[3 * n + 2], 6.f / 7, 1e-5f);
  }
}

TEST(TexelRaster, ThinSliverIslandStillProducesTexels) {
  // A sliver 0.1 texel tall in row 3 of 32, well below the row's centres (y = 3.5).
  const int W = 32;
  Mesh m;
  m.add(2.f / W, 3.1f / W, 20.f / W, 3.1f / W, 20.f / W, 3.2f / W);
  const TexelSet exact_only = raster(m, W, W, false);
  EXPECT_EQ(exact_only.size(), 0u);
  const TexelSet t = raster(m, W, W);
  EXPECT_EQ(t.stats.exact_texels, 0u);
  EXPECT_EQ(t.stats.conservative_texels, 18u);  // columns 2..19 of row 3
  for (std::size_t n = 0; n < t.size(); ++n) {
    EXPECT_EQ(t.pixels[n] / W, 3);
    EXPECT_EQ(t.exact[n], 0);
    const float* b = &t.barycentrics[3 * n];
    EXPECT_NEAR(b[0] + b[1] + b[2], 1.0f, 1e-6f);
    for (int k = 0; k < 3; ++k) EXPECT_GE(b[k], 0.0f);
  }
}

TEST(TexelRaster, ConservativeTexelsOnlyWhereNoCentreIsCovered) {
  Mesh m;
  m.add(0.13f, 0.11f, 0.87f, 0.23f, 0.41f, 0.93f);
  const TexelSet exact_only = raster(m, 40, 40, false);
  const TexelSet t = raster(m, 40, 40);
  EXPECT_EQ(exact_pixels(t), exact_pixels(exact_only));
  EXPECT_GT(t.stats.conservative_texels, 0u);
  EXPECT_TRUE(std::adjacent_find(t.pixels.begin(), t.pixels.end()) == t.pixels.end());
}

TEST(TexelRaster, DeterministicWhateverTheThreadCount) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  Mesh m;
  for (int k = 0; k < 3000; ++k) {
    const float u = U(rng), v = U(rng);
    m.add(u, v, u + 0.03f * U(rng), v + 0.01f * U(rng), u + 0.01f * U(rng), v + 0.03f * U(rng));
  }
  const int prev = set_max_threads(1);
  const TexelSet a = raster(m, 300, 700);
  set_max_threads(0);
  const TexelSet b = raster(m, 300, 700);
  set_max_threads(prev);
  EXPECT_EQ(a.pixels, b.pixels);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.exact, b.exact);
  EXPECT_EQ(a.stats.overlapping_texels, b.stats.overlapping_texels);
  EXPECT_GT(a.stats.overlapping_texels, 0u);
}

TEST(TexelRaster, ResolutionIsValidated) {
  Mesh m;
  m.add(0, 0, 1, 0, 0, 1);
  EXPECT_THROW(raster(m, 0, 16), std::invalid_argument);
  EXPECT_THROW(raster(m, 16, 16385), std::invalid_argument);
  EXPECT_NO_THROW(raster(m, 1, 1));
}

// === Splat and margin

TEST(TexelSplat, MarginFillsNTexelsAndNeverOverwritesCovered) {
  const int W = 21, H = 21, margin = 3;
  const std::int32_t pix[2] = {10 * W + 10, 10 * W + 11};
  const float val[2] = {0.25f, 0.75f};
  const TexelImage r = splat_texels(pix, val, 2, 1, W, H, margin, 1.0f);
  EXPECT_EQ(r.image.at(10, 10), 0.25f);
  EXPECT_EQ(r.image.at(11, 10), 0.75f);
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const int d = std::max(std::abs(y - 10), std::min(std::abs(x - 10), std::abs(x - 11)));
      const std::uint8_t m = r.mask[y * W + x];
      if (d == 0) {
        EXPECT_EQ(m, kTexelCovered);
      } else if (d <= margin) {
        EXPECT_EQ(m, kTexelMargin) << x << "," << y;
        EXPECT_GE(r.image.at(x, y), 0.25f);
        EXPECT_LE(r.image.at(x, y), 0.75f);
      } else {
        EXPECT_EQ(m, kTexelEmpty) << x << "," << y;
        EXPECT_EQ(r.image.at(x, y), 1.0f);
      }
    }
  }
  // Far left only sees the 0.25 texel's side.
  EXPECT_EQ(r.image.at(7, 10), 0.25f);
  EXPECT_EQ(r.image.at(14, 10), 0.75f);
}

TEST(TexelSplat, SeamBetweenIslandsGetsNoBackgroundWithinMargin) {
  // Two islands 5 texels apart with margin 3: the gap fills completely.
  const int W = 32, H = 32;
  Mesh m;
  m.add(2.f / W, 2.f / H, 12.f / W, 2.f / H, 12.f / W, 30.f / H);
  m.add(2.f / W, 2.f / H, 12.f / W, 30.f / H, 2.f / W, 30.f / H);
  m.add(17.f / W, 2.f / H, 30.f / W, 2.f / H, 30.f / W, 30.f / H);
  m.add(17.f / W, 2.f / H, 30.f / W, 30.f / H, 17.f / W, 30.f / H);
  const TexelSet t = raster(m, W, H);
  std::vector<float> values(t.size(), 0.5f);
  const TexelImage r = splat_texels(t.pixels.data(), values.data(), t.size(), 1, W, H, 3, 1.f);
  for (int y = 2; y < 30; ++y) {
    for (int x = 12; x < 17; ++x) {
      EXPECT_EQ(r.mask[y * W + x], kTexelMargin) << x << "," << y;
      EXPECT_EQ(r.image.at(x, y), 0.5f);
    }
  }
  int empty = 0;
  for (std::uint8_t k : r.mask) empty += k == kTexelEmpty;
  EXPECT_EQ(empty, 0);  // the whole 32² image lies within 3 texels of an island
}

TEST(TexelSplat, MultiChannelAndZeroMargin) {
  const std::int32_t pix[1] = {5};
  const float val[3] = {0.1f, 0.2f, 0.3f};
  const TexelImage r = splat_texels(pix, val, 1, 3, 4, 4, 0, 0.0f);
  EXPECT_EQ(r.image.at(1, 1, 2), 0.3f);
  EXPECT_EQ(r.image.at(0, 0, 0), 0.0f);
  EXPECT_EQ(r.mask[4], kTexelEmpty);
}

TEST(TexelSplat, BadInputThrows) {
  const std::int32_t bad[1] = {16};
  const float val[1] = {0.5f}, nan[1] = {NAN};
  const std::int32_t ok[1] = {3};
  EXPECT_THROW(splat_texels(bad, val, 1, 1, 4, 4, 1), std::invalid_argument);
  EXPECT_THROW(splat_texels(ok, nan, 1, 1, 4, 4, 1), std::invalid_argument);
  EXPECT_THROW(splat_texels(ok, val, 1, 1, 4, 4, -1), std::invalid_argument);
  EXPECT_THROW(splat_texels(ok, val, 1, 5, 4, 4, 1), std::invalid_argument);
}
