// Tests for the minimum-volume enclosing ellipsoid (ellipsoid_fit.h).
// Tolerances: containment exact (rel_tol 0, double evaluation of the float result); a known
// ellipsoid sampled on its surface is recovered within 2% on each radius and 2° on each axis;
// axes orthonormal to 1e-5 and right-handed (det > 0).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "test_points.h"
#include "canopy_ao/ellipsoid_fit.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/sphere_fit.h"

using namespace canopy_ao;
using canopy_ao::test::add;
using canopy_ao::test::view;

namespace {

// A rotation from Euler angles (z-y-x), columns = axes.
void rotation(double a, double b, double c, double R[3][3]) {
  const double ca = std::cos(a), sa = std::sin(a), cb = std::cos(b), sb = std::sin(b),
               cc = std::cos(c), sc = std::sin(c);
  const double Rz[3][3] = {{ca, -sa, 0}, {sa, ca, 0}, {0, 0, 1}};
  const double Ry[3][3] = {{cb, 0, sb}, {0, 1, 0}, {-sb, 0, cb}};
  const double Rx[3][3] = {{1, 0, 0}, {0, cc, -sc}, {0, sc, cc}};
  double T[3][3] = {};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) T[i][j] += Rz[i][k] * Ry[k][j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      R[i][j] = 0;
      for (int k = 0; k < 3; ++k) R[i][j] += T[i][k] * Rx[k][j];
    }
}

void expect_well_formed(const Ellipsoid& e) {
  for (int k = 0; k < 3; ++k) {
    EXPECT_TRUE(is_finite(e.axes[k]));
    EXPECT_NEAR(length(e.axes[k]), 1, 1e-5);
    EXPECT_GT(e.radii[k], 0);
    EXPECT_TRUE(std::isfinite(e.radii[k]));
    for (int l = k + 1; l < 3; ++l) EXPECT_NEAR(dot(e.axes[k], e.axes[l]), 0, 1e-5);
  }
  EXPECT_GT(dot(cross(e.axes[0], e.axes[1]), e.axes[2]), 0.999);
  EXPECT_GE(e.radii[0], e.radii[1]);
  EXPECT_GE(e.radii[1], e.radii[2]);
  EXPECT_TRUE(is_finite(e.center));
}

Ellipsoid fit_check(const std::vector<float>& p, const EllipsoidFitOptions& o = {},
                    EllipsoidFitInfo* info = nullptr) {
  const Ellipsoid e = fit_min_ellipsoid(view(p), o, info);
  expect_well_formed(e);
  EXPECT_TRUE(contains_all(e, view(p), 0.0)) << max_unit_norm2(e, view(p));
  return e;
}

}  // namespace

TEST(EllipsoidFit, RecoversRotatedEllipsoidFromSurfacePoints) {
  const double radii[3] = {5, 3, 1.5};
  double R[3][3];
  rotation(0.7, -0.4, 1.1, R);
  const double C[3] = {100, -20, 7};
  std::mt19937 g(1);
  std::normal_distribution<double> n01;
  std::vector<float> p;
  for (int i = 0; i < 5000; ++i) {
    double u[3] = {n01(g), n01(g), n01(g)};
    const double l = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    double x[3] = {C[0], C[1], C[2]};
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) x[r] += R[r][k] * radii[k] * u[k] / l;
    add(p, x[0], x[1], x[2]);
  }
  for (auto method : {EllipsoidMethod::Auto, EllipsoidMethod::Khachiyan}) {
    EllipsoidFitOptions o;
    o.method = method;
    EllipsoidFitInfo info;
    const Ellipsoid e = fit_check(p, o, &info);
    EXPECT_EQ(info.method_used, EllipsoidMethod::Khachiyan);
    EXPECT_TRUE(info.converged);
    EXPECT_EQ(info.dimension, 3);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(e.radii[k], radii[k], 0.02 * radii[k]) << "axis " << k;
      const Vec3 truth{float(R[0][k]), float(R[1][k]), float(R[2][k])};
      EXPECT_GT(std::abs(dot(e.axes[k], truth)), std::cos(2 * M_PI / 180)) << "axis " << k;
      EXPECT_NEAR(e.center[k], C[k], 0.02 * radii[2]);
    }
  }
  // PCA is looser but contains everything and keeps the axes.
  EllipsoidFitOptions o;
  o.method = EllipsoidMethod::Pca;
  const Ellipsoid pca = fit_check(p, o);
  EXPECT_GE(pca.volume(), 0.98f * 4.18879f * 5 * 3 * 1.5f);
}

TEST(EllipsoidFit, KhachiyanOnSubsampleStillContainsAll) {
  std::mt19937 g(2);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<float> p;
  for (int i = 0; i < 100000; ++i) add(p, 3 * u(g), 2 * u(g) + 0.3 * u(g), u(g));
  EllipsoidFitOptions o;
  o.max_points = 2000;
  EllipsoidFitInfo info;
  const Ellipsoid e = fit_check(p, o, &info);
  EXPECT_LE(info.active_points, 2000u);
  // The box [−3,3]×[−2.3,2.3]×[−1,1]: its MVEE has volume (√3)³ × box-inscribed volume.
  EXPECT_LT(e.volume(), 1.15 * 4.18879 * 3 * 2.3 * 1 * std::pow(3.0, 1.5));
}

TEST(EllipsoidFit, ThreadCountIndependent) {
  std::mt19937 g(4);
  std::normal_distribution<double> n01;
  std::vector<float> p;
  for (int i = 0; i < 200000; ++i) add(p, 2 * n01(g), n01(g), 0.5 * n01(g));
  const int old = set_max_threads(1);
  const Ellipsoid a = fit_min_ellipsoid(view(p));
  set_max_threads(0);
  const Ellipsoid b = fit_min_ellipsoid(view(p));
  set_max_threads(old);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(a.radii[k], b.radii[k]);
    EXPECT_EQ(a.center[k], b.center[k]);
  }
}

TEST(EllipsoidFit, SinglePointAndDuplicates) {
  for (int copies : {1, 500}) {
    std::vector<float> p;
    for (int i = 0; i < copies; ++i) add(p, 3, -4, 12);
    EllipsoidFitInfo info;
    const Ellipsoid e = fit_check(p, {}, &info);
    EXPECT_EQ(info.dimension, 0);
    const double floor = min_proxy_radius(Vec3{3, -4, 12});  // 1e-6 · (13 + 1)
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(e.radii[k], floor, 1e-3 * floor);
    EXPECT_NEAR(e.center.x, 3, 1e-6);
    EXPECT_NEAR(e.center.z, 12, 1e-6);
  }
}

TEST(EllipsoidFit, CollinearGivesSegmentWithDocumentedThickness) {
  std::vector<float> p;
  for (int i = 0; i <= 200; ++i) add(p, 1 + 0.02 * i, 2 + 0.04 * i, 3 + 0.04 * i);  // length 12
  EllipsoidFitInfo info;
  const Ellipsoid e = fit_check(p, {}, &info);
  EXPECT_EQ(info.dimension, 1);
  EXPECT_NEAR(e.radii[0], 6, 6e-4);
  EXPECT_NEAR(e.radii[1], 0.06, 1e-4);  // min_radius_ratio 1e-2 × the largest radius
  EXPECT_NEAR(e.radii[2], 0.06, 1e-4);
  EXPECT_NEAR(std::abs(e.axes[0].y), 2.0 / 3.0, 1e-5);
  EXPECT_NEAR(e.center.x, 3, 1e-5);
}

TEST(EllipsoidFit, FlatPatchGivesEllipseWithDocumentedThickness) {
  // A flat rectangular patch of grass in a tilted plane: the MVEE of a rectangle is the ellipse
  // through its corners with semi-axes √2 × the half-sides.
  double R[3][3];
  rotation(0.3, 0.5, -0.2, R);
  std::vector<float> p;
  for (int i = 0; i <= 40; ++i)
    for (int j = 0; j <= 20; ++j) {
      const double a = -4 + 0.2 * i, b = -2 + 0.2 * j;
      add(p, R[0][0] * a + R[0][1] * b, R[1][0] * a + R[1][1] * b, R[2][0] * a + R[2][1] * b);
    }
  EllipsoidFitInfo info;
  const Ellipsoid e = fit_check(p, {}, &info);
  EXPECT_EQ(info.dimension, 2);
  EXPECT_NEAR(e.radii[0], 4 * std::sqrt(2.0), 0.02 * 4 * std::sqrt(2.0));
  EXPECT_NEAR(e.radii[1], 2 * std::sqrt(2.0), 0.02 * 2 * std::sqrt(2.0));
  EXPECT_NEAR(e.radii[2], 0.01 * e.radii[0], 1e-4 * e.radii[0]);
  const Vec3 normal{float(R[0][2]), float(R[1][2]), float(R[2][2])};
  EXPECT_GT(std::abs(dot(e.axes[2], normal)), 0.9999);
}

TEST(EllipsoidFit, NearlyFlatStillClampedAndFinite) {
  // A leaf 1e-4 thick (< 1e-3 of its width): the 2-D path; 5e-3 thick: fitted in 3-D, then
  // clamped to 1e-2 of the largest radius.
  for (double t : {1e-4, 5e-3}) {
    std::mt19937 g(9);
    std::uniform_real_distribution<double> u(-1, 1);
    std::vector<float> p;
    for (int i = 0; i < 3000; ++i) add(p, u(g), u(g), t * u(g));
    const Ellipsoid e = fit_check(p);
    EXPECT_GE(e.radii[2], 0.01f * e.radii[0] * 0.999f);
    // The square's MVEE has radius √2 (2-D path); a thin 3-D box's has √3 × its half-sides.
    EXPECT_LT(e.radii[0], t < 1e-3 ? 1.42 : 1.74);
  }
}

TEST(EllipsoidFit, TrimIgnoresOutlier) {
  std::mt19937 g(5);
  std::normal_distribution<double> n01;
  std::vector<float> p;
  for (int i = 0; i < 1999; ++i) add(p, 3 * n01(g), n01(g), n01(g));
  add(p, 0, 40, 0);  // a branch far off the canopy's long axis
  EllipsoidFitOptions o;
  const Ellipsoid full = fit_check(p, o);
  EXPECT_GT(full.radii[0], 20);
  o.trim = 0.01;
  const Ellipsoid t = fit_min_ellipsoid(view(p), o);
  expect_well_formed(t);
  EXPECT_LT(t.radii[0], 12);
  EXPECT_LT(t.radii[1], 5);
  const auto keep = ellipsoid_trimmed_indices(view(p), 0.01);
  EXPECT_EQ(keep.size(), 1980u);
  EXPECT_NE(keep.back(), 1999u);
}

TEST(EllipsoidFit, BadInputThrows) {
  std::vector<float> empty, nan{0, 0, NAN}, ok{0, 0, 0};
  EXPECT_THROW(fit_min_ellipsoid(view(empty)), std::invalid_argument);
  EXPECT_THROW(fit_min_ellipsoid(view(nan)), std::invalid_argument);
  EllipsoidFitOptions o;
  o.trim = 0.5;
  EXPECT_THROW(fit_min_ellipsoid(view(ok), o), std::invalid_argument);
  o = {};
  o.tolerance = 0;
  EXPECT_THROW(fit_min_ellipsoid(view(ok), o), std::invalid_argument);
  o = {};
  o.max_points = 3;
  EXPECT_THROW(fit_min_ellipsoid(view(ok), o), std::invalid_argument);
}

TEST(EllipsoidFit, EigenSolver) {
  const double a[3][3] = {{4, 1, 0}, {1, 3, 1}, {0, 1, 2}};
  double w[3], v[3][3];
  symmetric_eigen(3, a, w, v);
  EXPECT_GT(w[0], w[1]);
  EXPECT_GT(w[1], w[2]);
  for (int k = 0; k < 3; ++k)
    for (int i = 0; i < 3; ++i) {
      double av = 0;
      for (int j = 0; j < 3; ++j) av += a[i][j] * v[j][k];
      EXPECT_NEAR(av, w[k] * v[i][k], 1e-12);
    }
}

TEST(EllipsoidFit, SimplexAndFarFromOrigin) {
  // The MVEE of a regular tetrahedron is its circumsphere (radius √3 for (±1, ±1, ±1) even).
  std::vector<float> tet;
  add(tet, 1, 1, 1);
  add(tet, 1, -1, -1);
  add(tet, -1, 1, -1);
  add(tet, -1, -1, 1);
  const Ellipsoid e = fit_check(tet);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(e.radii[k], std::sqrt(3.0), 2e-3 * std::sqrt(3.0));
  // A small cloud 1e4 away from the origin: still contains every point after float rounding.
  std::mt19937 g(12);
  std::normal_distribution<double> n01;
  std::vector<float> far;
  for (int i = 0; i < 5000; ++i) add(far, 1e4 + 0.3 * n01(g), -2e4 + 0.1 * n01(g), 0.05 * n01(g));
  const Ellipsoid f = fit_check(far);
  EXPECT_LT(f.radii[0], 2.0);
  // Two points: a segment, thickness 1e-2 of its half-length.
  std::vector<float> two;
  add(two, 0, 0, 0);
  add(two, 0, 2, 0);
  const Ellipsoid s = fit_check(two);
  EXPECT_NEAR(s.radii[0], 1, 1e-5);
  EXPECT_NEAR(s.radii[2], 0.01, 1e-6);
}
