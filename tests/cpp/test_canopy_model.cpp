// Canopy shell model (Hegeman Eq. 4–6, docs/DESIGN.md, 'The method ladder'), Reeves–Blau
// baseline and fast_exp.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "canopy_ao/canopy_model.h"
#include "canopy_ao/fast_math.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/reeves_blau.h"

using namespace canopy_ao;

namespace {
struct Receivers {
  std::vector<float> p, n;
  void add(Vec3 x, Vec3 nn) {
    p.insert(p.end(), {x.x, x.y, x.z});
    n.insert(n.end(), {nn.x, nn.y, nn.z});
  }
  std::size_t size() const { return p.size() / 3; }
  PointsView pv() const { return {p.data(), size()}; }
  PointsView nv() const { return {n.data(), size()}; }
};

Receivers random_receivers(std::size_t count, Vec3 c, float extent, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  Receivers r;
  for (std::size_t i = 0; i < count; ++i) {
    r.add(c + extent * Vec3{u(rng), u(rng), u(rng)}, Vec3{u(rng), u(rng), u(rng)});
  }
  return r;
}

std::vector<float> sphere_ao(const Receivers& r, const Sphere& s, float tau, float band = 0.1f) {
  std::vector<float> out(r.size());
  ao_canopy_sphere(r.pv(), r.nv(), s, CanopyOptions{tau, band}, out.data());
  return out;
}

Ellipsoid rotated_ellipsoid(Vec3 c, Vec3 radii, float angle) {
  Ellipsoid e;
  e.center = c;
  const float cs = std::cos(angle), sn = std::sin(angle);
  e.axes[0] = {cs, sn, 0};
  e.axes[1] = {-sn, cs, 0};
  e.axes[2] = {0, 0, 1};
  e.radii = radii;
  return e;
}
}  // namespace

// === fast_exp
TEST(FastMath, ExpRelativeErrorBelow1e6) {
  double worst = 0;
  for (int i = 0; i <= 2000000; ++i) {
    const float x = -87.3f + (88.3f + 87.3f) * static_cast<float>(i) / 2000000.0f;
    const double ref = std::exp(static_cast<double>(x));
    worst = std::max(worst, std::fabs(fast_exp(x) - ref) / ref);
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_EQ(fast_exp(0.0f), 1.0f);
  EXPECT_EQ(fast_exp(-100.0f), 0.0f);
  EXPECT_TRUE(std::isfinite(fast_exp(1000.0f)));
}

TEST(FastMath, AcosAndAtan2) {
  double worst_acos = 0, worst_atan = 0;
  for (int i = 0; i <= 200000; ++i) {
    const float y = -1.0f + 2.0f * static_cast<float>(i) / 200000.0f;
    worst_acos = std::max(worst_acos, std::fabs(fast_acos(y) - std::acos(double(y))));
  }
  for (int i = 0; i <= 2000; ++i) {
    for (float b : {0.0f, 1e-6f, 0.01f, 0.3f, 1.0f, 3.0f, 100.0f}) {
      const float a = 5.0f * static_cast<float>(i) / 2000.0f;
      worst_atan = std::max(worst_atan, std::fabs(fast_atan2_pos(a, b) - std::atan2(double(a), double(b))));
    }
  }
  EXPECT_LT(worst_acos, 1e-6);
  EXPECT_LT(worst_atan, 1e-6);
  EXPECT_EQ(fast_atan2_pos(0.0f, 0.0f), 0.0f);
}

// === Canopy sphere: closed forms
TEST(CanopySphere, CentreGivesExpMinusTauForAnyNormal) {
  const Sphere s{{1, 2, 3}, 2.5f};
  Receivers r;
  for (Vec3 n : {Vec3{1, 0, 0}, Vec3{0, -1, 0}, Vec3{0.3f, 0.4f, -0.8f}, Vec3{0, 0, 0}}) {
    r.add(s.center, n);
  }
  for (float tau : {0.0f, 0.5f, 1.0f, 3.0f}) {
    for (float v : sphere_ao(r, s, tau)) EXPECT_NEAR(v, std::exp(-tau), 2e-6f) << tau;
  }
}

TEST(CanopySphere, ShellPointFacingOutIsOpen) {
  const Sphere s{{0, 0, 0}, 3.0f};
  Receivers r;
  for (Vec3 d : {Vec3{1, 0, 0}, Vec3{0, 0, -1}, normalize(Vec3{1, 2, 3})}) r.add(3.0f * d, d);
  for (float v : sphere_ao(r, s, 2.0f)) EXPECT_NEAR(v, 1.0f, 1e-6f);
}

TEST(CanopySphere, MatchesHegemanFormulaInside) {
  // Direct evaluation of Eq. 4–6 with k = τ/Vhemi, in double.
  const Sphere s{{0.5f, -1, 2}, 1.7f};
  const Receivers r = random_receivers(2000, s.center, 1.7f / std::sqrt(3.0f), 7);
  const float tau = 1.3f;
  const auto v = sphere_ao(r, s, tau);
  const double R = s.radius, pi = 3.14159265358979;
  for (std::size_t i = 0; i < r.size(); ++i) {
    const Vec3 x = r.pv()[i], n = normalize(r.nv()[i]);
    const Vec3 cx = s.center - x;
    const double c = dot(cx, n);
    const double h = std::clamp(R + c, 0.0, 2 * R);
    const double d2 = std::max(0.0, double(dot(cx, cx)) - c * c);
    const double vcap = pi * h * h * (3 * R - h) / 3, vhemi = 2 * pi * R * R * R / 3;
    const double f = h * h / (h * h + d2);
    EXPECT_NEAR(v[i], std::exp(-tau / vhemi * f * vcap), 2e-5) << i;
  }
}

TEST(CanopySphere, ScaleInvariant) {
  const Sphere s{{0.2f, 0.1f, -0.3f}, 1.0f};
  const Receivers r = random_receivers(3000, s.center, 1.6f, 3);  // inside and outside
  const auto a = sphere_ao(r, s, 1.5f);
  for (float k : {0.01f, 37.0f}) {
    Receivers rk = r;
    for (float& c : rk.p) c *= k;
    const Sphere sk{s.center * k, s.radius * k};
    const auto b = sphere_ao(rk, sk, 1.5f);
    for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 2e-5f) << i << " k=" << k;
  }
}

TEST(CanopySphere, FiniteInUnitRangeAndThreadIndependent) {
  const Sphere s{{0, 0, 0}, 1.0f};
  Receivers r = random_receivers(50000, s.center, 3.0f, 11);
  for (int i = 0; i < 100; ++i) r.n[3 * i] = r.n[3 * i + 1] = r.n[3 * i + 2] = 0;  // zero normals
  r.add(s.center, {0, 0, 0});
  const int prev = set_max_threads(1);
  const auto one = sphere_ao(r, s, 2.0f);
  set_max_threads(2);
  const auto two = sphere_ao(r, s, 2.0f);
  set_max_threads(prev);
  for (std::size_t i = 0; i < one.size(); ++i) {
    ASSERT_TRUE(std::isfinite(one[i]));
    ASSERT_GE(one[i], 0.0f);
    ASSERT_LE(one[i], 1.0f);
    ASSERT_EQ(one[i], two[i]);
  }
}

TEST(CanopySphere, ZeroNormalFacesAwayFromCentre) {
  const Sphere s{{0, 0, 0}, 2.0f};
  Receivers r;
  r.add({1, 0.5f, 0}, {0, 0, 0});
  r.add({1, 0.5f, 0}, normalize(Vec3{1, 0.5f, 0}));
  const auto v = sphere_ao(r, s, 1.0f);
  EXPECT_FLOAT_EQ(v[0], v[1]);
}

TEST(CanopySphere, BadInputThrows) {
  Receivers r;
  r.add({0, 0, 0}, {0, 0, 1});
  std::vector<float> out(1);
  const Sphere ok{{0, 0, 0}, 1};
  EXPECT_THROW(ao_canopy_sphere(r.pv(), r.nv(), ok, {-1.0f}, out.data()), std::invalid_argument);
  EXPECT_THROW(ao_canopy_sphere(r.pv(), r.nv(), ok, {NAN}, out.data()), std::invalid_argument);
  EXPECT_THROW(ao_canopy_sphere(r.pv(), r.nv(), ok, {INFINITY}, out.data()),
               std::invalid_argument);
  EXPECT_THROW(ao_canopy_sphere(r.pv(), r.nv(), Sphere{{0, 0, 0}, 0}, {1}, out.data()),
               std::invalid_argument);
  EXPECT_THROW(ao_canopy_sphere(r.pv(), r.nv(), Sphere{{0, 0, 0}, -2}, {1}, out.data()),
               std::invalid_argument);
  EXPECT_THROW(ao_canopy_sphere(r.pv(), PointsView{r.n.data(), 0}, ok, {1}, out.data()),
               std::invalid_argument);
  Ellipsoid flat = Ellipsoid::from_sphere(ok);
  flat.radii.z = 0;
  EXPECT_THROW(ao_canopy_ellipsoid(r.pv(), r.nv(), flat, {1}, out.data()), std::invalid_argument);
}

// === Outside the shell
TEST(CanopySphere, OutsideUsesOccluderLawBeyondBand) {
  const Sphere s{{0, 0, 0}, 1.0f};
  const float tau = 1.0f;
  Receivers r;
  r.add({0, 0, -3}, {0, 0, 1});                   // facing the shell, 3 R below
  r.add({0, 0, -10}, {0, 0, 1});                  // far: nearly open
  r.add({0, 0, -3}, {0, 0, -1});                  // facing away: open
  r.add({0, 2, -2}, normalize(Vec3{0, -1, 1}));   // oblique
  const auto v = sphere_ao(r, s, tau);
  const float op = shell_opacity(tau);
  EXPECT_NEAR(v[0], 1 - op * (1.0f / 9.0f), 1e-6f);
  EXPECT_NEAR(v[1], 1 - op * (1.0f / 100.0f), 1e-6f);
  EXPECT_FLOAT_EQ(v[2], 1.0f);
  EXPECT_NEAR(v[3], 1 - op * (1.0f / 8.0f), 1e-6f);
  // The in-shell law applied blindly would give exp(−2τ) at any distance on the axis.
  EXPECT_GT(v[1], 0.99f);
}

TEST(CanopySphere, ContinuousAcrossTheShell) {
  // Walk radially through the surface for several normals: consecutive values never jump.
  const Sphere s{{0, 0, 0}, 1.0f};
  for (Vec3 n : {Vec3{0, 0, 1}, Vec3{0, 0, -1}, Vec3{1, 0, 0}, normalize(Vec3{1, 0, -1})}) {
    Receivers r;
    for (int i = 0; i <= 4000; ++i) r.add({0, 0, 0.9f + 0.3f * i / 4000.0f}, n);
    const auto v = sphere_ao(r, s, 2.0f);
    for (std::size_t i = 1; i < v.size(); ++i) ASSERT_LT(std::fabs(v[i] - v[i - 1]), 2e-3f) << i;
  }
  // With band = 0 the switch is hard and the jump (e.g. normal facing the centre) is visible.
  Receivers r;
  r.add({0, 0, 0.99999f}, {0, 0, -1});
  r.add({0, 0, 1.00001f}, {0, 0, -1});
  const auto v = sphere_ao(r, s, 1.0f, 0.0f);
  EXPECT_NEAR(v[0], std::exp(-2.0f), 1e-3f);
  EXPECT_NEAR(v[1], std::exp(-4.0f / 3.0f), 1e-3f);
}

// === Ellipsoid
TEST(CanopyEllipsoid, EqualAxesEqualsSphere) {
  const Sphere s{{1, -2, 0.5f}, 1.4f};
  Ellipsoid e = rotated_ellipsoid(s.center, {1.4f, 1.4f, 1.4f}, 0.7f);
  const Receivers r = random_receivers(5000, s.center, 2.5f, 5);
  const auto a = sphere_ao(r, s, 1.2f);
  std::vector<float> b(r.size());
  ao_canopy_ellipsoid(r.pv(), r.nv(), e, {1.2f}, b.data());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1e-5f) << i;
}

TEST(CanopyEllipsoid, CentreAndAffineInvariance) {
  const Ellipsoid e = rotated_ellipsoid({0, 0, 4}, {3, 1, 2}, 0.3f);
  Receivers r;
  r.add(e.center, {0, 1, 0});
  r.add(e.center + 3.0f * e.axes[0], e.axes[0]);  // on the shell, facing out
  std::vector<float> v(2);
  ao_canopy_ellipsoid(r.pv(), r.nv(), e, {0.8f}, v.data());
  EXPECT_NEAR(v[0], std::exp(-0.8f), 2e-6f);
  EXPECT_NEAR(v[1], 1.0f, 1e-6f);
  EXPECT_NEAR(canopy_visibility(r.pv()[0], r.nv()[0], e, {0.8f}), v[0], 1e-6f);
}

TEST(CanopyEllipsoid, OutsideMatchesOccluderLaw) {
  // Beyond the blend band the array path (vectorised, fast_acos/fast_atan2_pos) must give
  // occluders.h's occluder_visibility (scalar, libm) — incl. horizon-crossing receivers.
  const Ellipsoid e = rotated_ellipsoid({1, 0, 2}, {2.0f, 1.0f, 1.5f}, 0.4f);
  Receivers r;
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(-1, 1);
  while (r.size() < 20000) {
    const Vec3 x = e.center + 6.0f * Vec3{u(rng), u(rng), u(rng)};
    const Vec3 ux = e.to_unit(x);
    if (dot(ux, ux) < 1.12f * 1.12f) continue;  // beyond the band (0.1) only
    r.add(x, Vec3{u(rng), u(rng), u(rng)});
  }
  r.n[0] = r.n[1] = r.n[2] = 0;  // one zero normal
  std::vector<float> v(r.size());
  const float tau = 1.7f;
  ao_canopy_ellipsoid(r.pv(), r.nv(), e, {tau}, v.data());
  double worst = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    const float ref = occluder_visibility(r.pv()[i], r.nv()[i], e, shell_opacity(tau));
    worst = std::max(worst, double(std::fabs(v[i] - ref)));
  }
  EXPECT_LT(worst, 2e-6);
  EXPECT_EQ(v[0], 1.0f);
}

// === Several shells
TEST(CanopyShells, ProductEqualsSingleShellWhenOnlyOneMatters) {
  // Two shells; receivers inside A facing up, B far below their horizon: B contributes 1.
  const Ellipsoid a = rotated_ellipsoid({0, 0, 10}, {2, 2, 3}, 0.2f);
  const Ellipsoid b = rotated_ellipsoid({0, 0, -10}, {2, 1, 1}, 0.0f);
  Receivers r;
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-0.6f, 0.6f);
  for (int i = 0; i < 500; ++i) r.add(a.center + Vec3{u(rng), u(rng), u(rng)}, {u(rng), u(rng), 1});
  std::vector<float> one(r.size()), prod(r.size()), near(r.size());
  ao_canopy_ellipsoid(r.pv(), r.nv(), a, {1.0f}, one.data());
  ao_canopy_shells(r.pv(), r.nv(), {a, b}, {1.0f}, ShellCombine::Product, prod.data());
  ao_canopy_shells(r.pv(), r.nv(), {b, a}, {1.0f}, ShellCombine::Nearest, near.data());
  for (std::size_t i = 0; i < one.size(); ++i) {
    EXPECT_FLOAT_EQ(prod[i], one[i]);
    EXPECT_FLOAT_EQ(near[i], one[i]);
  }
}

TEST(CanopyShells, ProductOfOverlappingShellsAndNearestSeam) {
  // Two overlapping shells of different size; the nearest-centre boundary is x = 0.1.
  const Ellipsoid a = Ellipsoid::from_sphere({{-0.5f, 0, 0}, 1.0f});
  const Ellipsoid b = Ellipsoid::from_sphere({{0.7f, 0, 0}, 1.5f});
  Receivers r;
  for (int i = 0; i < 200; ++i) r.add({-0.2f + 0.6f * i / 199.0f, 0, 0.3f}, {0, 0, 1});
  std::vector<float> va(r.size()), vb(r.size()), prod(r.size()), near(r.size());
  ao_canopy_ellipsoid(r.pv(), r.nv(), a, {1.0f}, va.data());
  ao_canopy_ellipsoid(r.pv(), r.nv(), b, {1.0f}, vb.data());
  ao_canopy_shells(r.pv(), r.nv(), {a, b}, {1.0f}, ShellCombine::Product, prod.data());
  ao_canopy_shells(r.pv(), r.nv(), {a, b}, {1.0f}, ShellCombine::Nearest, near.data());
  float worst_prod = 0, worst_near = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    EXPECT_NEAR(prod[i], va[i] * vb[i], 1e-6f);
    const float x = r.pv()[i].x;
    if (std::fabs(x - 0.1f) > 1e-3f) EXPECT_FLOAT_EQ(near[i], x < 0.1f ? va[i] : vb[i]);
    if (i) {
      worst_prod = std::max(worst_prod, std::fabs(prod[i] - prod[i - 1]));
      worst_near = std::max(worst_near, std::fabs(near[i] - near[i - 1]));
    }
  }
  // The product is smooth across x = 0.1; the paper's nearest-centre rule jumps there (~0.15).
  EXPECT_LT(worst_prod, 0.01f);
  EXPECT_GT(worst_near, 0.1f);
}

// === Reeves–Blau
TEST(ReevesBlau, DepthLaw) {
  const Ellipsoid e = rotated_ellipsoid({1, 1, 1}, {2, 4, 1}, 0.5f);
  Receivers r;
  r.add(e.center, {0, 0, 1});
  r.add(e.center + 1.0f * e.axes[0], {0, 0, 1});  // half way along a (unit-frame depth 0.5)
  r.add(e.center + 4.0f * e.axes[1], {0, 0, 1});  // on the shell
  r.add(e.center + 9.0f * e.axes[2], {0, 0, 1});  // outside
  std::vector<float> v(r.size());
  ao_reeves_blau(r.pv(), e, 2.0f, v.data());
  EXPECT_NEAR(v[0], std::exp(-2.0f), 1e-6f);
  EXPECT_NEAR(v[1], std::exp(-1.0f), 1e-6f);
  EXPECT_NEAR(v[2], 1.0f, 1e-6f);
  EXPECT_FLOAT_EQ(v[3], 1.0f);
  EXPECT_THROW(ao_reeves_blau(r.pv(), e, -1.0f, v.data()), std::invalid_argument);
}

TEST(CanopySphere, ArrayPathMatchesOnePointPathForAnyLength) {
  // The array path deinterleaves AoS input in blocks of 8 with a scalar tail: every length and
  // offset must give the one-point values.
  const Ellipsoid e = rotated_ellipsoid({0.3f, -0.2f, 0.1f}, {1.5f, 1.0f, 0.8f}, 0.9f);
  for (std::size_t count : {1u, 7u, 8u, 9u, 255u, 256u, 257u, 1003u}) {
    const Receivers r = random_receivers(count, e.center, 1.6f, static_cast<unsigned>(count));
    std::vector<float> v(count);
    ao_canopy_ellipsoid(r.pv(), r.nv(), e, {1.1f}, v.data());
    for (std::size_t i = 0; i < count; ++i) {
      ASSERT_FLOAT_EQ(v[i], canopy_visibility(r.pv()[i], r.nv()[i], e, {1.1f})) << count << " " << i;
    }
  }
}
