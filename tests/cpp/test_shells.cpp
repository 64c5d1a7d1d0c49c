// Tests for k shells (shells.h). Tolerances: blobs 20 units apart with unit spread must be
// separated exactly (every label right up to a permutation); each shell contains its cluster
// up to float round-off (1e-5), its centroid is within 0.25 and its centre within 1.0 of the
// blob's (σ = 1).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>
#include <stdexcept>
#include <vector>

#include "test_points.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/shells.h"

using namespace canopy_ao;
using canopy_ao::test::view;

namespace {

struct Blobs {
  std::vector<float> pts;
  std::vector<int> truth;
};

Blobs make_blobs(const std::vector<Vec3>& centres, int per, unsigned seed) {
  std::mt19937 g(seed);
  std::normal_distribution<double> n01;
  Blobs b;
  // Interleaved, so cluster membership is not given away by the order.
  for (int i = 0; i < per; ++i)
    for (std::size_t c = 0; c < centres.size(); ++c) {
      b.pts.push_back(float(centres[c].x + n01(g)));
      b.pts.push_back(float(centres[c].y + 0.5 * n01(g)));
      b.pts.push_back(float(centres[c].z + 0.7 * n01(g)));
      b.truth.push_back(int(c));
    }
  return b;
}

void expect_recovers(const Blobs& b, const std::vector<Vec3>& centres, const ShellFit& f) {
  ASSERT_EQ(f.shells.size(), centres.size());
  ASSERT_EQ(f.labels.size(), b.truth.size());
  std::vector<int> map(centres.size(), -1);
  for (std::size_t i = 0; i < b.truth.size(); ++i) {
    int& m = map[b.truth[i]];
    if (m < 0) m = f.labels[i];
    EXPECT_EQ(f.labels[i], m) << "point " << i;
  }
  EXPECT_EQ(std::set<int>(map.begin(), map.end()).size(), centres.size());
  for (std::size_t c = 0; c < centres.size(); ++c) {
    const Ellipsoid& e = f.shells[map[c]];
    // The k-means centroid is a mean (σ/√400 ≈ 0.05); the shell's centre follows the blob's
    // extreme points, so it gets a looser bound.
    EXPECT_LT(length(f.centroids[map[c]] - centres[c]), 0.25);
    EXPECT_LT(length(e.center - centres[c]), 1.0);
    std::vector<float> mine;
    for (std::size_t i = 0; i < b.truth.size(); ++i)
      if (f.labels[i] == map[c]) mine.insert(mine.end(), &b.pts[3 * i], &b.pts[3 * i] + 3);
    double g = 0;
    for (std::size_t i = 0; i < mine.size() / 3; ++i) {
      const Vec3 u = e.to_unit(Vec3{mine[3 * i], mine[3 * i + 1], mine[3 * i + 2]});
      g = std::max(g, double(dot(u, u)));
    }
    EXPECT_LE(g, 1 + 1e-5);  // float to_unit; the double check is in the ellipsoid tests
  }
}

}  // namespace

TEST(ShellFit, RecoversTwoAndThreeBlobs) {
  const std::vector<Vec3> two = {{0, 0, 0}, {20, 5, 0}};
  const std::vector<Vec3> three = {{0, 0, 0}, {20, 0, 0}, {10, 20, 5}};
  for (auto kind : {ShellKind::Ellipsoid, ShellKind::Sphere}) {
    for (const auto& centres : {two, three}) {
      const Blobs b = make_blobs(centres, 400, 3);
      ShellFitOptions o;
      o.k = int(centres.size());
      o.kind = kind;
      o.seed = 42;
      const ShellFit f = fit_shells(view(b.pts), o);
      EXPECT_TRUE(f.converged);
      expect_recovers(b, centres, f);
      if (kind == ShellKind::Sphere)
        for (const auto& e : f.shells) {
          EXPECT_EQ(e.radii.x, e.radii.y);
          EXPECT_EQ(e.radii.x, e.radii.z);
        }
    }
  }
}

TEST(ShellFit, DeterministicForSeedAndThreadCount) {
  const Blobs b = make_blobs({{0, 0, 0}, {3, 0, 0}, {0, 3, 0}, {3, 3, 3}}, 5000, 8);
  ShellFitOptions o;
  o.k = 4;
  o.seed = 7;
  const int old = set_max_threads(1);
  const ShellFit a = fit_shells(view(b.pts), o);
  set_max_threads(0);
  const ShellFit c = fit_shells(view(b.pts), o);
  set_max_threads(old);
  EXPECT_EQ(a.labels, c.labels);
  ASSERT_EQ(a.shells.size(), c.shells.size());
  for (std::size_t s = 0; s < a.shells.size(); ++s)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(a.shells[s].radii[k], c.shells[s].radii[k]);
}

TEST(ShellFit, KLargerThanDistinctPoints) {
  std::vector<float> p;
  for (int i = 0; i < 50; ++i)
    for (float x : {0.0f, 4.0f, 8.0f}) p.insert(p.end(), {x, 1.0f, 2.0f});
  ShellFitOptions o;
  o.k = 7;
  const ShellFit f = fit_shells(view(p), o);
  ASSERT_EQ(f.shells.size(), 3u);  // one per distinct point, empty clusters dropped
  for (std::size_t i = 0; i < f.labels.size(); ++i) {
    ASSERT_GE(f.labels[i], 0);
    ASSERT_LT(f.labels[i], 3);
    EXPECT_NEAR(f.shells[f.labels[i]].center.x, p[3 * i], 1e-5);
    EXPECT_GT(f.shells[f.labels[i]].radii.z, 0);
  }
  // A single point with k > 1.
  const float one[3] = {1, 2, 3};
  const ShellFit g = fit_shells(PointsView{one, 1}, o);
  ASSERT_EQ(g.shells.size(), 1u);
  EXPECT_EQ(g.labels[0], 0);
}

TEST(ShellFit, OneShellEqualsTheWholeFit) {
  const Blobs b = make_blobs({{1, 2, 3}}, 2000, 4);
  ShellFitOptions o;
  o.k = 1;
  const ShellFit f = fit_shells(view(b.pts), o);
  ASSERT_EQ(f.shells.size(), 1u);
  const Ellipsoid e = fit_min_ellipsoid(view(b.pts));
  for (int k = 0; k < 3; ++k) EXPECT_EQ(f.shells[0].radii[k], e.radii[k]);
}

TEST(ShellFit, BadInputThrows) {
  std::vector<float> empty, nan{0, NAN, 0}, ok{0, 0, 0};
  ShellFitOptions o;
  EXPECT_THROW(fit_shells(view(empty), o), std::invalid_argument);
  EXPECT_THROW(fit_shells(view(nan), o), std::invalid_argument);
  o.k = 0;
  EXPECT_THROW(fit_shells(view(ok), o), std::invalid_argument);
  o.k = 2;
  o.trim = 0.6;
  EXPECT_THROW(fit_shells(view(ok), o), std::invalid_argument);
}
