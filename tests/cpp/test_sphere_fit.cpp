// Tests for the exact minimum enclosing sphere (sphere_fit.h).
// Tolerances: containment is exact (rel_tol 0) on the float result; the double result's
// Miniball self-check must be valid to 1e-9; radii match known answers to 1e-5 relative
// (the float result carries the documented 1e-6 inflation plus float rounding).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "test_points.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/sphere_fit.h"

using namespace canopy_ao;
using canopy_ao::test::add;
using canopy_ao::test::view;

namespace {

std::vector<float> random_cloud(std::size_t n, unsigned seed, double scale = 1.0,
                                double offset = 0.0) {
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<float> v;
  for (std::size_t i = 0; i < n; ++i) add(v, offset + scale * u(g), scale * u(g), scale * u(g));
  return v;
}

// Checks the float result contains all points and the exact result certifies itself.
Sphere fit_and_check(const std::vector<float>& pts) {
  const PointsView p = view(pts);
  const Sphere s = fit_min_sphere(p);
  EXPECT_TRUE(contains_all(s, p, 0.0));
  const MinSphere ms = min_sphere_exact(p);
  const SphereFitCheck chk = sphere_fit_check(p, ms);
  EXPECT_TRUE(chk.is_valid(1e-9)) << "max_excess " << chk.max_excess << " support_error "
                                  << chk.support_error << " subopt " << chk.suboptimality;
  EXPECT_GE(ms.support.size(), 1u);
  EXPECT_LE(ms.support.size(), 4u);
  return s;
}

// Brute force minimum enclosing sphere for small n: the smallest among spheres defined by
// 2, 3 or 4 points (diametral, circumcircle-in-plane, circumsphere) that contain all points.
double brute_force_radius(const std::vector<float>& pts) {
  const std::size_t n = pts.size() / 3;
  auto P = [&](std::size_t i) {
    return std::array<double, 3>{pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]};
  };
  double best = INFINITY;
  auto try_ball = [&](const std::array<double, 3>& c, double r) {
    if (!(r < best) || !std::isfinite(r)) return;
    for (std::size_t i = 0; i < n; ++i) {
      const auto p = P(i);
      const double d = std::sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                                 (p[2] - c[2]) * (p[2] - c[2]));
      if (d > r * (1 + 1e-9)) return;
    }
    best = r;
  };
  auto sub = [](std::array<double, 3> a, std::array<double, 3> b) {
    return std::array<double, 3>{a[0] - b[0], a[1] - b[1], a[2] - b[2]};
  };
  auto dot = [](std::array<double, 3> a, std::array<double, 3> b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  };
  // Circumcentre of 2–4 points in their affine hull: c = p0 + Σ μᵢ vᵢ, with
  // 2 vᵢ·(c − p0) = |vᵢ|² (Gram system, Cramer for ≤ 3 unknowns via elimination).
  auto circum = [&](std::vector<std::array<double, 3>> q) {
    const int k = int(q.size()) - 1;
    double g[3][4];
    std::vector<std::array<double, 3>> v;
    for (int i = 0; i < k; ++i) v.push_back(sub(q[i + 1], q[0]));
    for (int i = 0; i < k; ++i) {
      for (int j = 0; j < k; ++j) g[i][j] = 2 * dot(v[i], v[j]);
      g[i][k] = dot(v[i], v[i]);
    }
    for (int c = 0; c < k; ++c) {
      int piv = c;
      for (int r = c + 1; r < k; ++r)
        if (std::abs(g[r][c]) > std::abs(g[piv][c])) piv = r;
      for (int j = 0; j <= k; ++j) std::swap(g[c][j], g[piv][j]);
      if (std::abs(g[c][c]) < 1e-14) return;
      for (int r = 0; r < k; ++r) {
        if (r == c) continue;
        const double f = g[r][c] / g[c][c];
        for (int j = 0; j <= k; ++j) g[r][j] -= f * g[c][j];
      }
    }
    std::array<double, 3> c = q[0];
    for (int i = 0; i < k; ++i)
      for (int j = 0; j < 3; ++j) c[j] += g[i][k] / g[i][i] * v[i][j];
    const auto d = sub(q[0], c);
    try_ball(c, std::sqrt(dot(d, d)));
  };
  for (std::size_t a = 0; a < n; ++a)
    for (std::size_t b = a + 1; b < n; ++b) {
      circum({P(a), P(b)});
      for (std::size_t c = b + 1; c < n; ++c) {
        circum({P(a), P(b), P(c)});
        for (std::size_t d = c + 1; d < n; ++d) circum({P(a), P(b), P(c), P(d)});
      }
    }
  return best;
}

}  // namespace

TEST(SphereFit, TwoPoints) {
  std::vector<float> p;
  add(p, 1, 2, 3);
  add(p, 3, 2, 3);
  const Sphere s = fit_and_check(p);
  EXPECT_NEAR(s.center.x, 2, 1e-6);
  EXPECT_NEAR(s.center.y, 2, 1e-6);
  EXPECT_NEAR(s.radius, 1, 1e-5);
}

TEST(SphereFit, RegularTetrahedron) {
  // Vertices (±1, ±1, ±1) with an even number of minus signs: circumradius √3 at the origin.
  std::vector<float> p;
  add(p, 1, 1, 1);
  add(p, 1, -1, -1);
  add(p, -1, 1, -1);
  add(p, -1, -1, 1);
  const Sphere s = fit_and_check(p);
  EXPECT_NEAR(length(s.center), 0, 1e-6);
  EXPECT_NEAR(s.radius, std::sqrt(3.0), 1e-5 * std::sqrt(3.0));
  EXPECT_EQ(min_sphere_exact(view(p)).support.size(), 4u);
}

TEST(SphereFit, PointsOnSphereSurface) {
  // 2000 points on a sphere of radius 2.5 about (10, -3, 7), plus interior points.
  std::mt19937 g(3);
  std::normal_distribution<double> n01;
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<float> p;
  for (int i = 0; i < 3000; ++i) {
    double x = n01(g), y = n01(g), z = n01(g);
    const double l = std::sqrt(x * x + y * y + z * z);
    const double r = i < 2000 ? 2.5 : 2.5 * u(g);
    add(p, 10 + r * x / l, -3 + r * y / l, 7 + r * z / l);
  }
  const Sphere s = fit_and_check(p);
  EXPECT_NEAR(s.center.x, 10, 1e-3);
  EXPECT_NEAR(s.center.y, -3, 1e-3);
  EXPECT_NEAR(s.center.z, 7, 1e-3);
  EXPECT_NEAR(s.radius, 2.5, 2.5e-4);
}

TEST(SphereFit, RandomCloudsMatchBruteForce) {
  for (unsigned seed = 0; seed < 20; ++seed) {
    const auto p = random_cloud(5 + seed % 10, seed, 1.0 + seed, seed * 0.5);
    const Sphere s = fit_and_check(p);
    const double bf = brute_force_radius(p);
    EXPECT_NEAR(s.radius, bf, 1e-5 * bf) << "seed " << seed;
    EXPECT_NEAR(min_sphere_exact(view(p)).radius, bf, 1e-9 * bf) << "seed " << seed;
  }
}

TEST(SphereFit, DegenerateLatticeSetsMatchBruteForce) {
  // Points on the lattice {-1, 0, 1}³ (scaled, offset): duplicates, collinear, cocircular and
  // cospherical subsets everywhere — the inputs that break naive circumsphere code.
  std::mt19937 g(21);
  std::uniform_int_distribution<int> c(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<float> p;
    const int n = 2 + trial % 10;
    for (int i = 0; i < n; ++i) add(p, 3 + 0.5 * c(g), -7 + 0.5 * c(g), 0.5 * c(g));
    const Sphere s = fit_and_check(p);
    const double bf = brute_force_radius(p);
    if (bf == 0) {  // all duplicates: the documented floor
      EXPECT_NEAR(s.radius, min_proxy_radius(s.center), 1e-9);
    } else {
      EXPECT_NEAR(min_sphere_exact(view(p)).radius, bf, 1e-9 * bf) << "trial " << trial;
      EXPECT_NEAR(s.radius, bf, 1e-5 * bf) << "trial " << trial;
    }
  }
}

TEST(SphereFit, SinglePointAndDuplicates) {
  std::vector<float> one;
  add(one, 4, 5, 6);
  const Sphere s1 = fit_and_check(one);
  EXPECT_EQ(s1.center.x, 4);
  EXPECT_GT(s1.radius, 0);  // documented floor min_proxy_radius
  EXPECT_NEAR(s1.radius, min_proxy_radius(s1.center), 1e-9);

  std::vector<float> dup;
  for (int i = 0; i < 1000; ++i) add(dup, -1, 2, 0.5);
  const Sphere s2 = fit_and_check(dup);
  EXPECT_EQ(s2.center.y, 2);
  EXPECT_GT(s2.radius, 0);
  EXPECT_LT(s2.radius, 1e-5);

  // Duplicates of a real set do not change the answer.
  std::vector<float> two;
  for (int i = 0; i < 500; ++i) {
    add(two, 0, 0, 0);
    add(two, 0, 0, 4);
  }
  EXPECT_NEAR(fit_and_check(two).radius, 2, 2e-5);
}

TEST(SphereFit, Collinear) {
  std::vector<float> p;
  for (int i = 0; i <= 100; ++i) add(p, 1 + 0.1 * i, 2 + 0.2 * i, 3 - 0.3 * i);
  const Sphere s = fit_and_check(p);
  const double half = 50 * std::sqrt(0.14);  // 100 steps of |(0.1, 0.2, -0.3)|
  EXPECT_NEAR(s.radius, half, 1e-5 * half);
  EXPECT_NEAR(s.center.x, 6, 1e-5);
}

TEST(SphereFit, Coplanar) {
  // A square grid in z = 1 (many cocircular corners) and a circle in a tilted plane.
  std::vector<float> grid;
  for (int i = 0; i <= 20; ++i)
    for (int j = 0; j <= 20; ++j) add(grid, i * 0.1, j * 0.1, 1);
  const Sphere s = fit_and_check(grid);
  EXPECT_NEAR(s.radius, std::sqrt(2.0), 1e-5 * std::sqrt(2.0));
  EXPECT_NEAR(s.center.z, 1, 1e-6);

  std::vector<float> circ;
  for (int i = 0; i < 360; ++i) {
    const double a = i * M_PI / 180;
    add(circ, 3 * std::cos(a), 3 * std::sin(a) * 0.6, 3 * std::sin(a) * 0.8);
  }
  EXPECT_NEAR(fit_and_check(circ).radius, 3, 3e-5);
}

TEST(SphereFit, FarFromOriginStillContains) {
  const auto p = random_cloud(2000, 7, 0.01, 1000.0);
  const Sphere s = fit_and_check(p);
  EXPECT_LT(s.radius, 0.02);
}

TEST(SphereFit, LargeInputNoStackOverflowAndThreadIndependent) {
  const auto p = random_cloud(1000000, 11);
  const int old = set_max_threads(1);
  const Sphere a = fit_min_sphere(view(p));
  set_max_threads(0);
  const Sphere b = fit_min_sphere(view(p));
  set_max_threads(old);
  EXPECT_TRUE(contains_all(a, view(p)));
  EXPECT_EQ(a.radius, b.radius);
  EXPECT_EQ(a.center.x, b.center.x);
  EXPECT_LE(a.radius, std::sqrt(3.0) * (1 + 1e-5));
}

TEST(SphereFit, TrimIgnoresOutlier) {
  auto p = random_cloud(999, 5);  // cube [-1, 1]^3: untrimmed radius ≈ √3
  add(p, 50, 0, 0);               // one long branch tip
  const Sphere full = fit_min_sphere(view(p));
  EXPECT_GT(full.radius, 25);
  const Sphere t = fit_min_sphere(view(p), 0.01);
  EXPECT_LT(t.radius, 1.8);
  EXPECT_LT(length(t.center), 0.3);
  // It contains the points it kept.
  const auto keep = trimmed_indices(view(p), 0.01);
  EXPECT_EQ(keep.size(), 990u);
  for (std::size_t i : keep) EXPECT_NE(i, 999u);
}

TEST(SphereFit, BadInputThrows) {
  std::vector<float> empty;
  EXPECT_THROW(fit_min_sphere(view(empty)), std::invalid_argument);
  std::vector<float> nan{0, 0, NAN};
  EXPECT_THROW(fit_min_sphere(view(nan)), std::invalid_argument);
  std::vector<float> ok{0, 0, 0};
  EXPECT_THROW(fit_min_sphere(view(ok), 0.5), std::invalid_argument);
  EXPECT_THROW(fit_min_sphere(view(ok), -0.1), std::invalid_argument);
  EXPECT_THROW(fit_min_sphere(view(ok), NAN), std::invalid_argument);
}

// fit_min_sphere solves the exact problem on a core set and grows it by the points left
// outside: on inputs far larger than the core set it must give the one-shot exact ball.
TEST(SphereFit, CoreSetFitEqualsExactOnLargeInputs) {
  std::mt19937 g(17);
  std::normal_distribution<double> n01;
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<std::vector<float>> clouds;
  clouds.push_back(random_cloud(200000, 3, 2.0, 5.0));  // a cube
  {  // cospherical: every point on one sphere (the core set's worst case), a few inside
    std::vector<float> p;
    for (int i = 0; i < 100000; ++i) {
      const double x = n01(g), y = n01(g), z = n01(g), l = std::sqrt(x * x + y * y + z * z);
      const double r = i % 10 ? 3.0 : 3.0 * u(g);
      add(p, -4 + r * x / l, 2 + r * y / l, 9 + r * z / l);
    }
    clouds.push_back(p);
  }
  {  // a crown with a few far outliers at the end of the input (a stray branch)
    std::vector<float> p;
    for (int i = 0; i < 150000; ++i) add(p, 2.5 * n01(g), 2.5 * n01(g), 4 + 2 * n01(g));
    for (int i = 0; i < 5; ++i) add(p, 40.0 + i, -30.0, 12.0 * i);
    clouds.push_back(p);
  }
  {  // sorted along x (a strided sample sees the order, not a random one)
    auto p = random_cloud(120000, 9, 1.0);
    std::vector<std::array<float, 3>> rows(p.size() / 3);
    for (std::size_t i = 0; i < rows.size(); ++i) rows[i] = {p[3 * i], p[3 * i + 1], p[3 * i + 2]};
    std::sort(rows.begin(), rows.end());
    for (std::size_t i = 0; i < rows.size(); ++i)
      for (int k = 0; k < 3; ++k) p[3 * i + k] = rows[i][k];
    clouds.push_back(p);
  }
  for (std::size_t c = 0; c < clouds.size(); ++c) {
    const PointsView p = view(clouds[c]);
    const Sphere s = fit_min_sphere(p);
    const MinSphere ms = min_sphere_exact(p);
    ASSERT_TRUE(sphere_fit_check(p, ms).is_valid(1e-9)) << "cloud " << c;
    EXPECT_TRUE(contains_all(s, p, 0.0)) << "cloud " << c;
    // The same ball: the radius carries only the documented inflation and float rounding.
    EXPECT_GE(s.radius, ms.radius * (1 - 1e-7)) << "cloud " << c;
    EXPECT_LE(s.radius, ms.radius * (1 + 3e-6)) << "cloud " << c;
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(s.center[k], ms.center[k], 1e-6 * (ms.radius + std::fabs(ms.center[k])))
          << "cloud " << c;
  }
  // With a trim the same holds for the kept points.
  const PointsView p = view(clouds[2]);
  const auto keep = trimmed_indices(p, 0.01);
  const MinSphere ms = min_sphere_exact(p, &keep);
  const Sphere t = fit_min_sphere(p, 0.01);
  EXPECT_GE(t.radius, ms.radius * (1 - 1e-7));
  EXPECT_LE(t.radius, ms.radius * (1 + 3e-6));
}
