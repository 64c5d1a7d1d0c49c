// Bent normals from the ray tracer and the density grid (raytrace.h and density_grid.h, "Bent
// normals"; docs/DESIGN.md, 'Bent normals'): known directions, the documented fallbacks, and
// thread-count independence.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "canopy_ao/density_grid.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"
#include "test_points.h"

using namespace canopy_ao;

namespace {

constexpr float kPi = 3.14159265358979f;

/// A triangle soup in test_points.h's packing: xyz floats, three vertex indices per face.
struct Soup {
  std::vector<float> xyz;
  std::vector<std::int32_t> idx;
  std::int32_t vertex(Vec3 p) {
    test::add(xyz, p.x, p.y, p.z);
    return static_cast<std::int32_t>(xyz.size() / 3) - 1;
  }
  Vec3 at(std::int32_t k) const { return {xyz[3 * k], xyz[3 * k + 1], xyz[3 * k + 2]}; }
};

RayTracer tracer_of(const Soup& s) {
  return RayTracer(test::view(s.xyz), s.idx.data(), s.idx.size() / 3);
}

Vec3 unit(Vec3 a) { return a / length(a); }

/// The angle between a and b in degrees (both non-zero).
double degrees(Vec3 a, Vec3 b) {
  const double c = dot(a, b) / (length(a) * length(b));
  return std::acos(std::max(-1.0, std::min(1.0, c))) * 180.0 / kPi;
}

/// A unit hemisphere dome over the origin (z ≥ 0), with the facets whose centre lies within
/// `hole` degrees of `opening` left out (the one way out); hole = 0 closes it.
Soup dome(Vec3 opening, float hole, int stacks = 48, int slices = 96) {
  Soup m;
  for (int i = 0; i <= stacks; ++i) {
    const float th = 0.5f * kPi * i / stacks;  // from the pole down to the horizon
    for (int j = 0; j < slices; ++j) {
      const float ph = 2 * kPi * j / slices;
      m.vertex({std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)});
    }
  }
  const Vec3 d = unit(opening);
  auto keep = [&](int a, int b, int c) {
    const Vec3 centre = unit(m.at(a) + m.at(b) + m.at(c));
    if (hole <= 0 || degrees(centre, d) > hole) m.idx.insert(m.idx.end(), {a, b, c});
  };
  for (int i = 0; i < stacks; ++i) {
    for (int j = 0; j < slices; ++j) {
      const int a = i * slices + j, b = i * slices + (j + 1) % slices;
      keep(a, b, b + slices);
      keep(a, b + slices, a + slices);
    }
  }
  // The floor under the dome (z = 0, a little past its rim) closes it from below.
  const auto f0 = m.vertex({-2, -2, 0}), f1 = m.vertex({2, -2, 0}), f2 = m.vertex({2, 2, 0}),
             f3 = m.vertex({-2, 2, 0});
  m.idx.insert(m.idx.end(), {f0, f1, f2});
  m.idx.insert(m.idx.end(), {f0, f2, f3});
  return m;
}

RayTraceOptions opts(int samples, std::uint32_t seed = 0) {
  RayTraceOptions o;
  o.samples = samples;
  o.seed = seed;
  return o;
}

struct Traced {
  std::vector<float> ao, bent;
};

Traced trace(const RayTracer& tracer, const std::vector<float>& p, const std::vector<float>& n,
             const RayTraceOptions& o, const OwnPrimitives& own = {}) {
  const std::size_t count = p.size() / 3;
  Traced r{std::vector<float>(count), std::vector<float>(3 * count)};
  tracer.ao(PointsView{p.data(), count}, PointsView{n.data(), count}, own, o, r.ao.data(),
            r.bent.data());
  return r;
}

Vec3 row(const std::vector<float>& a, std::size_t i) {
  return {a[3 * i], a[3 * i + 1], a[3 * i + 2]};
}

}  // namespace

// === Ray tracer

TEST(BentNormals, UnderADomeWithOneOpeningTheyPointAtIt) {
  // Receivers on the floor near the dome's centre, normal up; the only way out is a 20° hole
  // 45° above the +x horizon (and, in a second dome, 70° up towards −y). The cosine-weighted
  // mean over the hole leans a hair towards the normal; measured < 1.5°, allowed 4°.
  for (const Vec3 opening : {Vec3{1, 0, 1}, Vec3{0, -0.364f, 1}}) {
    const RayTracer tracer = tracer_of(dome(opening, 20.0f));
    std::vector<float> p, n;
    for (int k = 0; k < 8; ++k) {
      p.insert(p.end(), {0.01f * (k % 3), 0.01f * (k / 3), 1e-3f});
      n.insert(n.end(), {0, 0, 1});
    }
    const Traced r = trace(tracer, p, n, opts(1024, 3));
    for (std::size_t i = 0; i < r.ao.size(); ++i) {
      EXPECT_LT(degrees(row(r.bent, i), opening), 4.0) << "receiver " << i;
      EXPECT_NEAR(length(row(r.bent, i)), 1.0, 1e-5);
      EXPECT_GT(r.ao[i], 0.01f);  // the hole is seen ...
      EXPECT_LT(r.ao[i], 0.2f);   // ... and nothing else
    }
  }
}

TEST(BentNormals, OnAnOpenPlaneTheyAreTheNormal) {
  // A large plane through the origin with a slanted normal; receivers on its own vertices
  // (every ray goes up and out), given the normal unnormalised. The mean of 256 stratified
  // cosine-weighted directions is the normal to within the lattice's residual (< 1°).
  const Vec3 nrm = unit(Vec3{1, 2, 3});
  const Vec3 t = unit(Vec3{2, -1, 0}), b = Vec3{nrm.y * t.z - nrm.z * t.y,
                                                nrm.z * t.x - nrm.x * t.z,
                                                nrm.x * t.y - nrm.y * t.x};
  Soup m;
  const int grid = 5;
  for (int i = 0; i < grid; ++i) {
    for (int j = 0; j < grid; ++j) m.vertex(t * (i - 2.0f) * 50.0f + b * (j - 2.0f) * 50.0f);
  }
  for (int i = 0; i + 1 < grid; ++i) {
    for (int j = 0; j + 1 < grid; ++j) {
      const int a = i * grid + j;
      m.idx.insert(m.idx.end(), {a, a + grid, a + grid + 1});
      m.idx.insert(m.idx.end(), {a, a + grid + 1, a + 1});
    }
  }
  const RayTracer tracer = tracer_of(m);
  std::vector<float> n;
  std::vector<std::int32_t> self;
  for (int k = 0; k < grid * grid; ++k) {
    n.insert(n.end(), {3 * nrm.x, 3 * nrm.y, 3 * nrm.z});
    self.push_back(k);
  }
  OwnPrimitives own;
  own.vertex_ids = self.data();
  for (const int samples : {256, 1024}) {
    const Traced r = trace(tracer, m.xyz, n, opts(samples), own);
    for (std::size_t i = 0; i < r.ao.size(); ++i) {
      EXPECT_EQ(r.ao[i], 1.0f);
      EXPECT_LT(degrees(row(r.bent, i), nrm), 1.0) << samples << " rays, vertex " << i;
    }
  }
}

TEST(BentNormals, EveryRayBlockedGivesTheNormalAndAZeroNormalGivesZero) {
  const RayTracer closed = tracer_of(dome({0, 0, 1}, 0.0f));
  const std::vector<float> p = {0, 0, 1e-3f, 0.1f, 0, 1e-3f, 0, 0, 1e-3f};
  const std::vector<float> n = {0, 0, 2, 0.3f, 0, 1, 0, 0, 0};
  const Traced r = trace(closed, p, n, opts(64));
  EXPECT_EQ(r.ao[0], 0.0f);
  EXPECT_EQ(r.ao[1], 0.0f);
  EXPECT_NEAR(degrees(row(r.bent, 0), {0, 0, 1}), 0.0, 1e-3);  // the unit normal
  EXPECT_NEAR(length(row(r.bent, 0)), 1.0, 1e-6);
  EXPECT_NEAR(degrees(row(r.bent, 1), {0.3f, 0, 1}), 0.0, 1e-3);
  EXPECT_EQ(r.ao[2], 1.0f);  // zero normal: AO 1, bent (0, 0, 0)
  EXPECT_EQ(row(r.bent, 2).x, 0.0f);
  EXPECT_EQ(row(r.bent, 2).y, 0.0f);
  EXPECT_EQ(row(r.bent, 2).z, 0.0f);

  // An empty scene: nothing blocks, the bent normal is the unit normal.
  const RayTracer none(PointsView{nullptr, 0}, nullptr, 0);
  const Traced e = trace(none, p, n, opts(16));
  EXPECT_NEAR(degrees(row(e.bent, 1), {0.3f, 0, 1}), 0.0, 1e-3);
  EXPECT_EQ(row(e.bent, 2).z, 0.0f);
}

TEST(BentNormals, SameBitsWhateverTheThreadCountAndTheAoUnchanged) {
  // Random leaves in a ball, receivers on their vertices with random normals.
  Soup leaves;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1, 1);
  std::normal_distribution<float> g;
  for (int k = 0; k < 1500; ++k) {
    Vec3 c;
    do c = {u(rng), u(rng), u(rng)};
    while (dot(c, c) > 1);
    const auto a = leaves.vertex(c * 2.0f);
    leaves.vertex(c * 2.0f + 0.25f * Vec3{u(rng), u(rng), u(rng)});
    leaves.vertex(c * 2.0f + 0.25f * Vec3{u(rng), u(rng), u(rng)});
    leaves.idx.insert(leaves.idx.end(), {a, a + 1, a + 2});
  }
  std::vector<float> n(leaves.xyz.size());
  for (float& x : n) x = g(rng);
  const RayTracer tracer = tracer_of(leaves);
  for (const Sampling s : {Sampling::kLattice, Sampling::kSobol}) {
    RayTraceOptions o = opts(100, 5);  // not a multiple of the stream: rays split over flushes
    o.sampling = s;
    const int prev = set_max_threads(1);
    const Traced one = trace(tracer, leaves.xyz, n, o);
    set_max_threads(2);
    const Traced two = trace(tracer, leaves.xyz, n, o);
    set_max_threads(prev);
    EXPECT_EQ(one.bent, two.bent);
    EXPECT_EQ(one.ao, two.ao);
    const std::size_t count = n.size() / 3;
    std::vector<float> plain(count);
    tracer.ao(test::view(leaves.xyz), PointsView{n.data(), count}, o, plain.data());
    EXPECT_EQ(one.ao, plain);  // asking for bent normals does not change the AO
    // Partly blocked receivers lean away from the normal, never below its horizon by more
    // than the cosine-weighted mean allows (it lies inside the hemisphere: dot > 0).
    std::size_t bent_away = 0;
    for (std::size_t i = 0; i < count; ++i) {
      const Vec3 nn = unit(row(n, i)), bn = row(one.bent, i);
      EXPECT_GT(dot(bn, nn), 0.0f);
      bent_away += one.ao[i] > 0.0f && one.ao[i] < 1.0f && degrees(bn, nn) > 5.0;
    }
    EXPECT_GT(bent_away, count / 4);
  }
}

// === Density grid

TEST(BentNormals, GridLeansAwayFromADenseCanopyAsTheRaysDo) {
  // A dense ball of leaves to the −x side of receivers on the ground looking up: both the
  // rays and the grid's transmittance-weighted mean lean towards +x, within 15° of each other.
  Soup leaves;
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int k = 0; k < 6000; ++k) {
    Vec3 c;
    do c = {u(rng), u(rng), u(rng)};
    while (dot(c, c) > 1);
    c = Vec3{-1.5f, 0, 1.5f} + c;
    const auto a = leaves.vertex(c);
    leaves.vertex(c + 0.15f * Vec3{u(rng), u(rng), u(rng)});
    leaves.vertex(c + 0.15f * Vec3{u(rng), u(rng), u(rng)});
    leaves.idx.insert(leaves.idx.end(), {a, a + 1, a + 2});
  }
  const std::vector<float> p = {0, 0, 0, 0.3f, 0.2f, 0, -0.2f, -0.3f, 0};
  const std::vector<float> n = {0, 0, 1, 0, 0, 1, 0, 0, 1};
  const Traced rays = trace(tracer_of(leaves), p, n, opts(1024));
  const DensityGrid grid(test::view(leaves.xyz), leaves.idx.data(), leaves.idx.size() / 3);
  std::vector<float> ao(3), bent(9);
  DensityAOOptions go;
  go.directions = 256;
  grid.ao(PointsView{p.data(), 3}, PointsView{n.data(), 3}, go, ao.data(), bent.data());
  std::vector<float> plain(3);
  grid.ao(PointsView{p.data(), 3}, PointsView{n.data(), 3}, go, plain.data());
  EXPECT_EQ(ao, plain);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_GT(row(rays.bent, i).x, 0.1f) << i;
    EXPECT_GT(row(bent, i).x, 0.1f) << i;
    EXPECT_NEAR(length(row(bent, i)), 1.0, 1e-5);
    EXPECT_LT(degrees(row(bent, i), row(rays.bent, i)), 15.0) << i;
  }
  // An empty grid and a zero normal: the ray tracer's fallbacks.
  const DensityGrid empty(PointsView{nullptr, 0}, nullptr, 0);
  const std::vector<float> n2 = {0, 0, 3, 0, 0, 0, 1, 0, 0};
  empty.ao(PointsView{p.data(), 3}, PointsView{n2.data(), 3}, go, ao.data(), bent.data());
  EXPECT_EQ(row(bent, 0).z, 1.0f);
  EXPECT_EQ(row(bent, 2).x, 1.0f);
  grid.ao(PointsView{p.data(), 3}, PointsView{n2.data(), 3}, go, ao.data(), bent.data());
  EXPECT_EQ(row(bent, 1).x, 0.0f);
  EXPECT_EQ(row(bent, 1).y, 0.0f);
  EXPECT_EQ(row(bent, 1).z, 0.0f);
}
