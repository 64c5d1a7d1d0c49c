// Tests of the tabulated uniform-medium expectation (medium_table.h).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "canopy_ao/medium_table.h"
#include "canopy_ao/parallel.h"

using namespace canopy_ao;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Independent reference: the 2D hemisphere integral, cosine-weighted by Malley's map (u = sin²θ
// uniform), midpoint rule on an n×n grid, chords from a plain ray–sphere intersection.
double direct_2d(double r, double cos_beta, double tau, int n) {
  const double sb = std::sqrt(std::max(0.0, 1 - cos_beta * cos_beta));
  // receiver at (0, 0, r), radial axis +z, normal in the xz plane; frame (t1, t2, n)
  const double nx = sb, nz = cos_beta;
  const double t1x = nz, t1z = -nx;  // ⟂ n in the xz plane; t2 = (0, 1, 0)
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double u = (i + 0.5) / n;
    const double st = std::sqrt(u), ct = std::sqrt(1 - u);
    for (int j = 0; j < n; ++j) {
      const double phi = 2 * kPi * (j + 0.5) / n;
      const double a = st * std::cos(phi), b = st * std::sin(phi);
      const double wx = a * t1x + ct * nx, wy = b, wz = a * t1z + ct * nz;
      const double bq = r * wz;  // x·ω
      const double disc = bq * bq - (r * r - 1);
      double len = 0;
      if (disc > 0) {
        const double s = std::sqrt(disc);
        const double t0 = -bq - s, t1 = -bq + s;
        if (t1 > 0) len = t1 - std::max(t0, 0.0);
      }
      (void)wx;
      (void)wy;
      sum += std::exp(-tau * len);
    }
  }
  return sum / (double(n) * n);
}

}  // namespace

TEST(MediumTable, OneDQuadratureMatchesDirect2DIntegration) {
  // The 1D reduction (closed-form azimuth) against brute-force 2D integration: |Δ| < 1e-3
  // (the 2D midpoint rule's own error at the cone edge outside the sphere dominates).
  for (double r : {0.0, 0.35, 0.8, 1.0, 1.6, 4.0}) {
    for (double c : {-0.9, -0.2, 0.4, 1.0}) {
      for (double tau : {0.5, 3.0, 12.0}) {
        const double ref = direct_2d(r, c, tau, 500);
        EXPECT_NEAR(medium_ao_quadrature(r, c, tau), ref, 1e-3)
            << "r=" << r << " cos=" << c << " tau=" << tau;
      }
    }
  }
}

TEST(MediumTable, LookupMatchesQuadratureOffGrid) {
  // Off-grid points across the whole table, including just inside/outside the surface and past
  // the table's last radius: |ΔAO| < 1e-3.
  const MediumTable& t = MediumTable::get();
  double worst = 0;
  for (double r : {0.07, 0.29, 0.53, 0.77, 0.91, 0.985, 1.0, 1.04, 1.37, 2.3, 5.1, 7.7, 11.0}) {
    for (double c = -0.987; c <= 1.0; c += 0.1531) {
      for (double tau : {0.03, 0.41, 1.3, 2.9, 6.7, 15.3, 29.0}) {
        const double ref = medium_ao_quadrature(r, c, tau, 1024);
        const double got = t.ao(float(r), float(c), float(tau));
        worst = std::max(worst, std::abs(got - ref));
        ASSERT_NEAR(got, ref, 1e-3) << "r=" << r << " cos=" << c << " tau=" << tau;
      }
    }
  }
  std::printf("[medium table] worst |table - quadrature| at off-grid points: %.2e\n", worst);
}

TEST(MediumTable, CentreIsExactlyExpMinusTau) {
  const MediumTable& t = MediumTable::get();
  for (float c : {-1.0f, -0.3f, 0.0f, 0.6f, 1.0f}) {
    for (float tau : {0.1f, 1.0f, 2.5f, 7.0f, 20.0f}) {
      EXPECT_NEAR(t.ao(0.0f, c, tau) / std::exp(-tau), 1.0f, 1e-5f);
    }
  }
  EXPECT_NEAR(medium_ao_quadrature(0.0, 0.3, 2.0), std::exp(-2.0), 1e-9);
}

TEST(MediumTable, ZeroDensityIsOpenSky) {
  const MediumTable& t = MediumTable::get();
  for (float r : {0.0f, 0.5f, 1.0f, 3.0f, 20.0f})
    for (float c : {-1.0f, 0.0f, 1.0f}) EXPECT_EQ(t.ao(r, c, 0.0f), 1.0f);
}

TEST(MediumTable, MonotoneInDensity) {
  const MediumTable& t = MediumTable::get();
  for (float r : {0.0f, 0.2f, 0.6f, 0.95f, 1.0f, 1.5f, 4.0f, 10.0f}) {
    for (float c = -1.0f; c <= 1.0f; c += 0.125f) {
      float prev = 1.0f;
      for (float tau = 0.0f; tau < 40.0f; tau += 0.05f) {
        const float v = t.ao(r, c, tau);
        ASSERT_LE(v, prev + 1e-6f) << "r=" << r << " cos=" << c << " tau=" << tau;
        prev = v;
      }
    }
  }
}

TEST(MediumTable, SurfaceFacingOutIsOpen) {
  const MediumTable& t = MediumTable::get();
  for (float tau : {0.5f, 4.0f, 30.0f}) {
    EXPECT_NEAR(t.ao(1.0f, 1.0f, tau), 1.0f, 1e-5f);
    EXPECT_NEAR(t.ao(2.0f, 1.0f, tau), 1.0f, 1e-5f);
    // facing the centre from just outside: the sphere fills the hemisphere
    EXPECT_NEAR(t.ao(1.0f, -1.0f, tau), medium_ao_quadrature(1.0, -1.0, tau), 2e-3);
  }
}

TEST(MediumTable, FarFieldFallsOffLikeSolidAngle) {
  // Beyond the table (r > 8) occlusion ∝ 1/r²; facing the centre the exact far-field limit of
  // the occlusion is the disc's mean opacity times (1/r)².
  const MediumTable& t = MediumTable::get();
  for (double r : {9.0, 20.0, 100.0}) {
    const double ref = medium_ao_quadrature(r, -1.0, 3.0, 1024);
    EXPECT_NEAR(1 - t.ao(float(r), -1.0f, 3.0f), 1 - ref, 0.02 * (1 - ref) + 1e-6);
  }
}

TEST(MediumTable, SphereAndEllipsoidAgree) {
  // A round ellipsoid is the sphere; also exercises the per-point entry points.
  std::vector<float> pos, nrm;
  for (int i = 0; i < 500; ++i) {
    const float a = 0.37f * i, b = 0.11f * i;
    pos.insert(pos.end(), {1 + 2.5f * std::sin(a) * std::cos(b), -2 + 2.5f * std::sin(b),
                           0.5f + 2.5f * std::cos(a) * std::cos(b) * (i % 3) / 2});
    nrm.insert(nrm.end(), {std::cos(b), std::sin(a), std::cos(a)});
  }
  const PointsView p{pos.data(), 500}, n{nrm.data(), 500};
  const Sphere s{{1, -2, 0.5f}, 2.0f};
  std::vector<float> a(500), b(500), c(500);
  ao_medium_sphere(p, n, s, 2.0f, a.data());
  ao_medium_ellipsoid(p, n, Ellipsoid::from_sphere(s), 2.0f, b.data());
  ao_medium_shells(p, n, {Ellipsoid::from_sphere(s)}, {2.0f}, MediumCombine::Product, c.data());
  for (int i = 0; i < 500; ++i) {
    ASSERT_NEAR(a[i], b[i], 1e-5f);
    ASSERT_NEAR(a[i], c[i], 1e-5f);
    ASSERT_GE(a[i], 0.0f);
    ASSERT_LE(a[i], 1.0f);
  }
}

TEST(MediumTable, ThreadCountIndependent) {
  std::vector<float> pos, nrm;
  for (int i = 0; i < 5000; ++i) {
    pos.insert(pos.end(), {std::sin(0.7f * i) * 1.3f, std::cos(1.1f * i), std::sin(0.3f * i)});
    nrm.insert(nrm.end(), {std::cos(0.2f * i), 0.5f, std::sin(0.9f * i)});
  }
  const PointsView p{pos.data(), 5000}, n{nrm.data(), 5000};
  std::vector<float> a(5000), b(5000);
  const int prev = set_max_threads(1);
  ao_medium_sphere(p, n, Sphere{{0.1f, 0, 0}, 1.2f}, 3.0f, a.data());
  set_max_threads(0);
  ao_medium_sphere(p, n, Sphere{{0.1f, 0, 0}, 1.2f}, 3.0f, b.data());
  set_max_threads(prev);
  EXPECT_EQ(a, b);
}

TEST(MediumTable, BadInputThrows) {
  std::vector<float> pos = {0, 0, NAN}, nrm = {0, 0, 1}, out(1);
  const PointsView p{pos.data(), 1}, n{nrm.data(), 1};
  EXPECT_THROW(ao_medium_sphere(p, n, Sphere{{0, 0, 0}, 1}, 1, out.data()),
               std::invalid_argument);
  pos[2] = 0;
  EXPECT_THROW(ao_medium_sphere(p, n, Sphere{{0, 0, 0}, 0}, 1, out.data()),
               std::invalid_argument);
  EXPECT_THROW(ao_medium_sphere(p, n, Sphere{{0, 0, 0}, 1}, -1, out.data()),
               std::invalid_argument);
  EXPECT_THROW(ao_medium_sphere(p, n, Sphere{{0, 0, 0}, 1}, NAN, out.data()),
               std::invalid_argument);
  EXPECT_THROW(ao_medium_shells(p, n, {}, {1.0f, 2.0f}, MediumCombine::Product, out.data()),
               std::invalid_argument);
}
