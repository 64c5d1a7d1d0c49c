// The canopy-shell kernels chosen at run time (canopy_model.h, "Kernels"): the portable and the
// AVX2/FMA kernel give the same values, and both follow the one scalar definition of Hegeman's
// law (hegeman_exponent, Eq. 5–6).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "canopy_ao/canopy_model.h"

using namespace canopy_ao;

namespace {

struct Points {
  std::vector<float> p, n;
  std::size_t size() const { return p.size() / 3; }
  PointsView pv() const { return {p.data(), size()}; }
  PointsView nv() const { return {n.data(), size()}; }
};

// Receivers around a unit-scale shell at c (inside, in the blend band and far outside), with a
// few zero normals; a count that is no multiple of 8 (the padded last group).
Points mixed_points(Vec3 c, float extent, std::size_t count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  Points r;
  for (std::size_t i = 0; i < count; ++i) {
    r.p.insert(r.p.end(), {c.x + extent * u(rng), c.y + extent * u(rng), c.z + extent * u(rng)});
    if (i % 97 == 0) {
      r.n.insert(r.n.end(), {0, 0, 0});
    } else {
      r.n.insert(r.n.end(), {u(rng), u(rng), u(rng)});
    }
  }
  return r;
}

// Restores the kernel in force when the test started.
struct KernelGuard {
  CanopyKernel prev = canopy_kernel();
  ~KernelGuard() { set_canopy_kernel(prev); }
};

template <class F>
std::vector<float> with_kernel(CanopyKernel k, std::size_t n, F&& f) {
  KernelGuard g;
  set_canopy_kernel(k);
  std::vector<float> out(n, -1.0f);
  f(out.data());
  return out;
}

Ellipsoid tilted(Vec3 c) {
  Ellipsoid e;
  e.center = c;
  const float cs = std::cos(0.6f), sn = std::sin(0.6f);
  e.axes[0] = {cs, sn, 0};
  e.axes[1] = {-sn, cs, 0};
  e.axes[2] = {0, 0, 1};
  e.radii = {3.0f, 1.5f, 2.0f};
  return e;
}

}  // namespace

TEST(CanopyKernels, HegemanExponentIsEq6) {
  // Centre (h = 1, d = 0): τ for any τ, so V = exp(−τ). Surface facing the centre (h = 2): 2τ.
  // Surface facing out (h = 0): nothing above the tangent plane.
  EXPECT_FLOAT_EQ(hegeman_exponent(1.0f, 0.0f, 1.7f), 1.7f);
  EXPECT_FLOAT_EQ(hegeman_exponent(2.0f, 0.0f, 1.0f), 2.0f);
  EXPECT_FLOAT_EQ(hegeman_exponent(0.0f, 0.0f, 1.0f), 0.0f);
  // f = h²/(h² + d²) halves the exponent where d² = h².
  EXPECT_FLOAT_EQ(hegeman_exponent(0.5f, 0.25f, 1.0f), 0.5f * (0.25f * 2.5f / 2.0f));
}

TEST(CanopyKernels, PortableAlwaysAvailableAvx2AsTheCpuSays) {
  EXPECT_TRUE(canopy_kernel_available(CanopyKernel::Portable));
  if (!canopy_kernel_available(CanopyKernel::Avx2)) {
    EXPECT_THROW(set_canopy_kernel(CanopyKernel::Avx2), std::invalid_argument);
    EXPECT_EQ(canopy_kernel(), CanopyKernel::Portable);
    return;
  }
  KernelGuard g;
  set_canopy_kernel(CanopyKernel::Portable);
  EXPECT_EQ(canopy_kernel(), CanopyKernel::Portable);
  set_canopy_kernel(CanopyKernel::Avx2);
  EXPECT_EQ(canopy_kernel(), CanopyKernel::Avx2);
}

// Inside the shell, with a non-zero normal, both kernels give exp(−hegeman_exponent) with
// h = 1 + dot(C − x, n̂), d² = |x − C|² − c² (unit sphere): the vectorised paths against the
// scalar definition.
TEST(CanopyKernels, BothFollowTheScalarLawInside) {
  const Sphere s{{0.5f, -1.0f, 2.0f}, 1.0f};
  const float tau = 1.3f;
  Points r = mixed_points(s.center, 0.57f, 1003, 5);  // |x − C| < 0.99: all inside
  for (std::size_t i = 0; i < r.size(); i += 97) r.n[3 * i] = 1.0f;  // no zero normals here
  std::vector<float> ref(r.size());
  for (std::size_t i = 0; i < r.size(); ++i) {
    const float ux = r.p[3 * i] - s.center.x, uy = r.p[3 * i + 1] - s.center.y,
                uz = r.p[3 * i + 2] - s.center.z;
    const float nx = r.n[3 * i], ny = r.n[3 * i + 1], nz = r.n[3 * i + 2];
    const float len = std::sqrt(nx * nx + ny * ny + nz * nz);
    const float c = -(ux * nx + uy * ny + uz * nz) / len;
    const float d2 = std::max(ux * ux + uy * uy + uz * uz - c * c, 0.0f);
    ref[i] = std::exp(-hegeman_exponent(1.0f + c, d2, tau));
  }
  for (CanopyKernel k : {CanopyKernel::Portable, CanopyKernel::Avx2}) {
    if (!canopy_kernel_available(k)) continue;
    const auto v = with_kernel(k, r.size(), [&](float* o) {
      ao_canopy_sphere(r.pv(), r.nv(), s, {tau, 0.1f}, o);
    });
    for (std::size_t i = 0; i < r.size(); ++i)
      ASSERT_NEAR(v[i], ref[i], 2e-6f) << "kernel " << static_cast<int>(k) << " point " << i;
  }
}

// Everywhere (inside, band, outside, zero normals), for the sphere, the ellipsoid and several
// shells, and one point at a time: the two kernels agree.
TEST(CanopyKernels, Avx2AgreesWithPortable) {
  if (!canopy_kernel_available(CanopyKernel::Avx2)) GTEST_SKIP() << "CPU without AVX2/FMA";
  const Sphere s{{0, 0, 6}, 5.0f};
  const Ellipsoid e = tilted({1, 2, 3});
  const std::vector<Ellipsoid> shells = {e, tilted({4, 2, 3}), Ellipsoid::from_sphere(s)};
  const Points r = mixed_points({1, 2, 4}, 9.0f, 4099, 11);
  const CanopyOptions o{0.9f, 0.2f};
  auto both = [&](auto&& f) {
    return std::make_pair(with_kernel(CanopyKernel::Portable, r.size(), f),
                          with_kernel(CanopyKernel::Avx2, r.size(), f));
  };
  const auto sp = both([&](float* out) { ao_canopy_sphere(r.pv(), r.nv(), s, o, out); });
  const auto el = both([&](float* out) { ao_canopy_ellipsoid(r.pv(), r.nv(), e, o, out); });
  const auto pr = both([&](float* out) {
    ao_canopy_shells(r.pv(), r.nv(), shells, o, ShellCombine::Product, out);
  });
  const auto ne = both([&](float* out) {
    ao_canopy_shells(r.pv(), r.nv(), shells, o, ShellCombine::Nearest, out);
  });
  int inside = 0, open = 0;
  for (const auto* pair : {&sp, &el, &pr, &ne}) {
    for (std::size_t i = 0; i < r.size(); ++i) {
      ASSERT_NEAR(pair->first[i], pair->second[i], 2e-6f) << i;
      ASSERT_GE(pair->second[i], 0.0f);
      ASSERT_LE(pair->second[i], 1.0f);
      inside += pair->second[i] < 0.5f;
      open += pair->second[i] > 0.99f;
    }
  }
  EXPECT_GT(inside, 100);  // the points do exercise both laws
  EXPECT_GT(open, 100);
  for (std::size_t i = 0; i < r.size(); i += 37) {
    const Vec3 x{r.p[3 * i], r.p[3 * i + 1], r.p[3 * i + 2]};
    const Vec3 n{r.n[3 * i], r.n[3 * i + 1], r.n[3 * i + 2]};
    const auto one = both([&](float* out) { *out = canopy_visibility(x, n, e, o); });
    EXPECT_NEAR(one.first[0], one.second[0], 2e-6f) << i;
    EXPECT_NEAR(one.second[0], el.second[i], 2e-6f) << i;
  }
}
