// Known answers for the Embree AO reference (raytrace.h). Every expected value is a closed
// form for cosine-weighted AO (docs/DESIGN.md, 'What AO means here'); tolerances are stated next to each check.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <vector>

#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"

using namespace canopy_ao;

namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kInf = std::numeric_limits<float>::infinity();

struct Mesh {
  std::vector<float> v;
  std::vector<std::int32_t> t;
  PointsView view() const { return {v.data(), v.size() / 3}; }
  std::size_t triangles() const { return t.size() / 3; }
  std::int32_t add(Vec3 p) {
    v.insert(v.end(), {p.x, p.y, p.z});
    return static_cast<std::int32_t>(v.size() / 3 - 1);
  }
  void tri(std::int32_t a, std::int32_t b, std::int32_t c) { t.insert(t.end(), {a, b, c}); }
  // Quad a-b-c-d as two triangles; `flip` reverses the winding (occluders are two-sided).
  void quad(Vec3 a, Vec3 b, Vec3 c, Vec3 d, bool flip = false) {
    const auto ia = add(a), ib = add(b), ic = add(c), id = add(d);
    if (flip) {
      tri(ia, ic, ib);
      tri(ia, id, ic);
    } else {
      tri(ia, ib, ic);
      tri(ia, ic, id);
    }
  }
  RayTracer tracer() const { return RayTracer(view(), t.data(), triangles()); }
  // The tracer with vertex normals: vertex receivers start at Cycles' bake point.
  RayTracer baking(const std::vector<float>& normals,
                   const std::vector<std::int32_t>* polygons = nullptr) const {
    BakeShading shading;
    shading.vertex_normals = {normals.data(), normals.size() / 3};
    shading.polygons = polygons ? polygons->data() : nullptr;
    return RayTracer(view(), t.data(), triangles(), shading, {}, {});
  }
};

// The same normal for every vertex of m, packed xyz.
std::vector<float> same_normals(const Mesh& m, Vec3 n) {
  std::vector<float> out;
  for (std::size_t i = 0; i < m.v.size() / 3; ++i) out.insert(out.end(), {n.x, n.y, n.z});
  return out;
}

// Horizontal rectangle [x0, x1] × [y0, y1] at height z.
Mesh horizontal(float x0, float x1, float y0, float y1, float z, bool flip = false) {
  Mesh m;
  m.quad({x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}, flip);
  return m;
}

// Closed axis-aligned cube [-h, h]³, 12 triangles sharing 8 vertices (watertight).
Mesh cube(float h) {
  Mesh m;
  for (int i = 0; i < 8; ++i) m.add({i & 1 ? h : -h, i & 2 ? h : -h, i & 4 ? h : -h});
  const int f[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                       {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : f) {
    m.tri(q[0], q[1], q[2]);
    m.tri(q[0], q[2], q[3]);
  }
  return m;
}

// UV sphere (stacks × slices), inscribed: the faceting error in blocked solid angle is
// ~1 − cos(π/stacks), below 1e-3 relative at 64 stacks.
Mesh uv_sphere(Vec3 c, float r, int stacks, int slices) {
  Mesh m;
  for (int i = 0; i <= stacks; ++i) {
    const float th = kPi * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const float ph = 2 * kPi * j / slices;
      m.add(c + r * Vec3{std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)});
    }
  }
  for (int i = 0; i < stacks; ++i) {
    for (int j = 0; j < slices; ++j) {
      const int a = i * slices + j, b = i * slices + (j + 1) % slices;
      const int c2 = a + slices, d = b + slices;
      m.tri(a, b, d);
      m.tri(a, d, c2);
    }
  }
  return m;
}

// Random small triangles in a ball: a stand-in for a tree canopy.
Mesh canopy(int triangles, float radius, float leaf, std::uint32_t seed) {
  Mesh m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int k = 0; k < triangles; ++k) {
    Vec3 p;
    do p = {u(rng), u(rng), u(rng)};
    while (dot(p, p) > 1);
    p = p * radius;
    const auto a = m.add(p);
    const auto b = m.add(p + leaf * Vec3{u(rng), u(rng), u(rng)});
    const auto c = m.add(p + leaf * Vec3{u(rng), u(rng), u(rng)});
    m.tri(a, b, c);
  }
  return m;
}

// N copies of one receiver: each row gets its own rotation, so their spread shows the noise.
struct Receivers {
  std::vector<float> p, n;
  Receivers(Vec3 point, Vec3 normal, std::size_t count) {
    for (std::size_t i = 0; i < count; ++i) {
      p.insert(p.end(), {point.x, point.y, point.z});
      n.insert(n.end(), {normal.x, normal.y, normal.z});
    }
  }
  PointsView points() const { return {p.data(), p.size() / 3}; }
  PointsView normals() const { return {n.data(), n.size() / 3}; }
};

// n random (Gaussian, so isotropic, not unit) normals, packed xyz.
std::vector<float> random_normals(std::size_t n, std::uint32_t seed) {
  std::vector<float> nrm(3 * n);
  std::mt19937 rng(seed);
  std::normal_distribution<float> g;
  for (float& x : nrm) x = g(rng);
  return nrm;
}

double mean(const std::vector<float>& a) {
  return std::accumulate(a.begin(), a.end(), 0.0) / static_cast<double>(a.size());
}

// A closed prism (the trunk or a branch): `sides` facets around the axis from `base` along unit
// `axis` for `length`, circumradius r, both ends capped. Ring vertex k sits at angle
// phi0 + 2πk/sides in the (e1, e2) plane; facet k (vertices k, k+1) faces the angle
// phi0 + π(2k+1)/sides. Returns the index of ring vertex 0 at the base.
std::int32_t prism(Mesh* m, Vec3 base, Vec3 axis, Vec3 e1, Vec3 e2, float r, float length,
                   int sides, float phi0) {
  const std::int32_t first = static_cast<std::int32_t>(m->v.size() / 3);
  for (int end = 0; end < 2; ++end) {
    for (int k = 0; k < sides; ++k) {
      const float ph = phi0 + 2 * kPi * k / sides;
      m->add(base + axis * (end * length) + r * (std::cos(ph) * e1 + std::sin(ph) * e2));
    }
  }
  const std::int32_t c0 = m->add(base), c1 = m->add(base + axis * length);
  for (int k = 0; k < sides; ++k) {
    const std::int32_t b0 = first + k, b1 = first + (k + 1) % sides;
    const std::int32_t t0 = b0 + sides, t1 = b1 + sides;
    m->tri(b0, b1, t1);
    m->tri(b0, t1, t0);
    m->tri(c0, b1, b0);
    m->tri(c1, t0, t1);
  }
  return first;
}

// Mean and worst row of `ao` against `want`.
void expect_ao(const std::vector<float>& ao, double want, const char* what) {
  EXPECT_NEAR(mean(ao), want, 0.005) << what;  // bias well below 0.01
  for (float v : ao) EXPECT_NEAR(v, want, 0.03) << what;
}

RayTraceOptions opts(int samples, float distance = kInf, std::uint32_t seed = 0,
                     float offset = -1) {
  RayTraceOptions o;
  o.samples = samples;
  o.distance = distance;
  o.seed = seed;
  o.offset = offset;
  return o;
}

}  // namespace

// === Open sky and planes

TEST(RayTracer, PointOnOpenGroundIsOne) {
  // The receiver lies on the plane itself: the origin offset must keep it from seeing it.
  const Mesh ground = horizontal(-1000, 1000, -1000, 1000, 0);
  const Receivers r({0.3f, -0.2f, 0}, {0, 0, 1}, 16);
  for (float v : ground.tracer().ao(r.points(), r.normals(), opts(256))) EXPECT_EQ(v, 1.0f);
}

TEST(RayTracer, FarFromTheOriginTheAutoOffsetStillClearsTheGround) {
  // 1 km away, float spacing is ~1e-4: the automatic offset scales with the coordinates too.
  const Mesh ground = horizontal(9000, 11000, 9000, 11000, 500);
  const Receivers r({10000.3f, 10000.1f, 500}, {0, 0, 1}, 16);
  for (float v : ground.tracer().ao(r.points(), r.normals(), opts(256))) EXPECT_EQ(v, 1.0f);
}

TEST(RayTracer, AutoOffsetIsSmallAgainstTheScene) {
  const Mesh ground = horizontal(-100, 100, -100, 100, 0);
  const float diag = std::sqrt(2.0f) * 200;
  EXPECT_GT(ground.tracer().auto_offset(), 0.0f);
  EXPECT_LT(ground.tracer().auto_offset(), 2e-5f * diag);
}

TEST(RayTracer, UnderALargeCeilingIsBlockedUnlessTheDistanceIsShorter) {
  const float h = 1;
  const Mesh ceiling = horizontal(-100, 100, -100, 100, h);
  const RayTracer tracer = ceiling.tracer();
  const Receivers r({0, 0, 0}, {0, 0, 1}, 32);
  // Unblocked: only rays within atan(h/100) of the horizon, cos-weighted fraction ~1e-4.
  for (float v : tracer.ao(r.points(), r.normals(), opts(256))) EXPECT_LE(v, 1.0f / 256);
  // D < h: nothing within reach, exactly open.
  for (float v : tracer.ao(r.points(), r.normals(), opts(256, 0.9f * h))) EXPECT_EQ(v, 1.0f);
  // D = 2h: rays with cos θ ≥ h/D hit, a cos-weighted fraction sin²(60°) = 3/4 ⇒ AO = 1/4.
  // (An explicit offset: the automatic one, 3e-3 here, would shift the answer by 0.0014.)
  const auto ao = tracer.ao(r.points(), r.normals(), opts(1024, 2 * h, 0, 1e-5f));
  for (float v : ao) EXPECT_NEAR(v, 0.25, 0.01);  // stratified: ~N^-3/4 noise
  EXPECT_NEAR(mean(ao), 0.25, 0.003);
}

TEST(RayTracer, TrianglesAreTwoSided) {
  const Receivers r({0, 0, 0}, {0, 0, 1}, 32);
  const auto a = horizontal(-50, 50, -50, 50, 1, false).tracer().ao(r.points(), r.normals(),
                                                                     opts(256, 3));
  const auto b = horizontal(-50, 50, -50, 50, 1, true).tracer().ao(r.points(), r.normals(),
                                                                    opts(256, 3));
  // Seen from below, one winding faces away from the receiver: both must block the same.
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1.0 / 256);
  EXPECT_NEAR(mean(a), 1.0 / 9.0, 0.005);  // cos θ ≥ 1/3 blocked: sin² = 8/9
}

TEST(RayTracer, UnderTheEdgeOfAHalfPlaneIsHalfOpen) {
  // Overhang z = 1, x ≥ 0: rays with dx > 0 hit it (a cos-weighted half, by symmetry).
  const Mesh roof = horizontal(0, 200, -200, 200, 1);
  const RayTracer tracer = roof.tracer();
  const Receivers r({0, 0, 0}, {0, 0, 1}, 64);
  const auto ao = tracer.ao(r.points(), r.normals(), opts(1024));
  EXPECT_NEAR(mean(ao), 0.5, 0.003);
  for (float v : ao) EXPECT_NEAR(v, 0.5, 0.01);
  // With D = 2: half of the 3/4 of the unlimited ceiling ⇒ AO = 5/8.
  EXPECT_NEAR(mean(tracer.ao(r.points(), r.normals(), opts(1024, 2, 0, 1e-5f))), 0.625, 0.003);
}

TEST(RayTracer, BesideATallWallIsHalfOpen) {
  // Wall x = 1, the receiver on the ground facing up: every direction with dx > 0 hits it.
  Mesh wall;
  wall.quad({1, -300, -1}, {1, 300, -1}, {1, 300, 300}, {1, -300, 300});
  const Receivers r({0, 0, 0}, {0, 0, 1}, 64);
  EXPECT_NEAR(mean(wall.tracer().ao(r.points(), r.normals(), opts(1024))), 0.5, 0.003);
}

// === Closed shapes

TEST(RayTracer, InsideAClosedBoxIsZero) {
  const RayTracer tracer = cube(1).tracer();
  const Receivers r({0, 0, 0}, {0, 0, 1}, 16);
  for (float v : tracer.ao(r.points(), r.normals(), opts(1024))) EXPECT_EQ(v, 0.0f);
}

TEST(RayTracer, BoxCornersAtTheirOwnVertices) {
  // ao_at_vertices skips the faces meeting at each corner, as Cycles skips what a ray starts
  // on. Outward normals: nothing of the convex box is in front of a corner ⇒ 1. Inward normals
  // (n = the octant's diagonal): only the directions into the box's octant are blocked, a
  // cosine-weighted fraction ∫_octant ω·n dω / π = 3·(π/4)/(√3 π) = √3/4 ⇒ AO = 1 − √3/4.
  const Mesh box = cube(1);
  const RayTracer tracer = box.tracer();
  std::vector<float> in, out;
  for (std::size_t i = 0; i < box.v.size(); ++i) {
    in.push_back(-box.v[i] / std::sqrt(3.0f));
    out.push_back(box.v[i] / std::sqrt(3.0f));
  }
  for (float v : tracer.ao_at_vertices({out.data(), 8}, opts(512))) EXPECT_EQ(v, 1.0f);
  const auto inward = tracer.ao_at_vertices({in.data(), 8}, opts(1024));
  expect_ao(inward, 1.0 - std::sqrt(3.0) / 4.0, "inward corner");
}

TEST(RayTracer, SolidSphereAboveTheHorizonBlocksRSquaredOverDSquaredCosTheta) {
  // A sphere of angular radius σ (sin σ = r/d) whose centre is θ from the normal, wholly
  // above the horizon (θ + σ < 90°), blocks (r/d)² cos θ of cosine-weighted AO (the
  // projected-solid-angle form factor of a sphere).
  const float r = 1, d = 4;
  for (float theta_deg : {0.0f, 30.0f, 60.0f}) {
    const float th = theta_deg * kPi / 180;
    const Mesh ball = uv_sphere({d * std::sin(th), 0, d * std::cos(th)}, r, 64, 128);
    const Receivers rc({0, 0, 0}, {0, 0, 1}, 64);
    const auto ao = ball.tracer().ao(rc.points(), rc.normals(), opts(1024));
    const double want = 1.0 - (r / d) * (r / d) * std::cos(th);
    for (float v : ao) EXPECT_NEAR(v, want, 0.01) << "theta " << theta_deg;
    EXPECT_NEAR(mean(ao), want, 0.002) << "theta " << theta_deg;
  }
}

// === Receivers on the mesh: skip only their own triangles (Cycles' rule)
// Each case is a receiver whose own surface touches another one; the closed forms follow from
// the tilted-plane law: directions behind a plane through the receiver with unit normal m form
// a cosine-weighted fraction (1 − n·m)/2 of its hemisphere, and every such direction enters a
// solid lying behind that plane at once. An origin offset along the normal gets all of them
// wrong (checked by hand: the blade root and the trunk base read 1.0, the leaf facing the
// branch 0.0).

TEST(RayTracer, BladeRootOnTheGroundSeesTheGroundBelowItsHorizon) {
  // A flat blade standing on the ground, leaning back by β; its root vertex and a texel on
  // its bottom edge. Facing down (n·up = −sin β) or up (+sin β): AO = (1 + n·up)/2.
  for (float beta_deg : {0.0f, 20.0f}) {
    const float beta = beta_deg * kPi / 180;
    Mesh m = horizontal(-100, 100, -100, 100, 0);
    const Vec3 up_blade{0, std::sin(beta), std::cos(beta)}, side{0.012f, 0, 0};
    const Vec3 root{0.3f, -0.2f, 0};
    const std::int32_t r0 = m.add(root - side), r1 = m.add(root + side);
    const std::int32_t t1 = m.add(root + side + 0.3f * up_blade);
    const std::int32_t t0 = m.add(root - side + 0.3f * up_blade);
    m.tri(r0, r1, t1);  // triangle 2: holds the bottom edge
    m.tri(r0, t1, t0);
    const RayTracer tracer = m.tracer();
    for (float facing : {1.0f, -1.0f}) {
      const Vec3 n = facing * Vec3{0, std::cos(beta), -std::sin(beta)};
      const double want = (1.0 + n.z) / 2.0;
      const Receivers at_root(m.view()[static_cast<std::size_t>(r0)], n, 64);
      const std::vector<std::int32_t> vid(64, r0), none(64, -1), tid(64, 2);
      OwnPrimitives own;
      own.vertex_ids = vid.data();
      std::vector<float> ao(64);
      tracer.ao(at_root.points(), at_root.normals(), own, opts(1024), ao.data());
      expect_ao(ao, want, "root vertex");
      // A texel on the bottom edge, on triangle 2 (the vertex ids all −1: no vertex).
      const Receivers texel(root, n, 64);
      own.vertex_ids = none.data();
      own.triangle_ids = tid.data();
      tracer.ao(texel.points(), texel.normals(), own, opts(1024), ao.data());
      expect_ao(ao, want, "bottom-edge texel");
    }
  }
}

TEST(RayTracer, TrunkBaseOnTheGroundIsHalfOpen) {
  // A 16-sided capped trunk on the ground; a base-ring vertex with its radial (smooth) normal.
  // Below the horizon: the ground. Above it nothing: near a convex vertex the trunk lies behind
  // both facet planes meeting there, and no direction of the radial hemisphere is behind both.
  const int sides = 16;
  Mesh m = horizontal(-100, 100, -100, 100, 0);
  const std::int32_t b0 = prism(&m, {0, 0, 0}, {0, 0, 1}, {1, 0, 0}, {0, 1, 0}, 0.2f, 3.0f,
                                sides, 0.0f);
  const Receivers r(m.view()[static_cast<std::size_t>(b0)], {1, 0, 0}, 64);
  const std::vector<std::int32_t> vid(64, b0);
  OwnPrimitives own;
  own.vertex_ids = vid.data();
  std::vector<float> ao(64);
  m.tracer().ao(r.points(), r.normals(), own, opts(1024), ao.data());
  expect_ao(ao, 0.5, "trunk base");
}

TEST(RayTracer, LeafLyingOnABranchSeesTheBranchBehindTheFacet) {
  // An 8-sided capped branch along y, its top facet at z = r cos(π/8); a leaf's base edge lies
  // on that facet and the leaf rises at α = 45°. Its base vertex, facing up or down
  // (n·up = ±cos α): the convex branch blocks exactly the directions behind the facet.
  const int sides = 8;
  const float r = 0.05f, alpha = kPi / 4;
  Mesh m;
  prism(&m, {0, -1, 0}, {0, 1, 0}, {1, 0, 0}, {0, 0, 1}, r, 2.0f, sides, kPi / 2 - kPi / sides);
  const Vec3 x0{0.005f, 0.1f, r * std::cos(kPi / sides)}, along{0, 0.03f, 0};
  const Vec3 rise = 0.1f * Vec3{std::cos(alpha), 0, std::sin(alpha)};
  const std::int32_t l0 = m.add(x0), l1 = m.add(x0 + along), l2 = m.add(x0 + along + rise),
                     l3 = m.add(x0 + rise);
  m.tri(l0, l1, l2);
  m.tri(l0, l2, l3);
  const RayTracer tracer = m.tracer();
  const std::vector<std::int32_t> vid(64, l0);
  OwnPrimitives own;
  own.vertex_ids = vid.data();
  for (float facing : {1.0f, -1.0f}) {
    const Vec3 n = facing * Vec3{-std::sin(alpha), 0, std::cos(alpha)};
    const Receivers rc(x0, n, 64);
    std::vector<float> ao(64);
    tracer.ao(rc.points(), rc.normals(), own, opts(1024), ao.data());
    expect_ao(ao, (1.0 + n.z) / 2.0, facing > 0 ? "leaf facing up" : "leaf facing the branch");
  }
}

TEST(RayTracer, OwnPrimitiveIdsAreChecked) {
  const Mesh box = cube(1);
  const RayTracer tracer = box.tracer();
  const Receivers r({1, 1, 1}, {1, 1, 1}, 2);
  std::vector<float> out(2);
  for (std::vector<std::int32_t> bad : {std::vector<std::int32_t>{0, 8},
                                        std::vector<std::int32_t>{-2, 0}}) {
    OwnPrimitives own;
    own.vertex_ids = bad.data();
    EXPECT_THROW(tracer.ao(r.points(), r.normals(), own, opts(8), out.data()),
                 std::invalid_argument);
  }
  const std::vector<std::int32_t> tri_bad{0, 12};
  OwnPrimitives own;
  own.triangle_ids = tri_bad.data();
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), own, opts(8), out.data()),
               std::invalid_argument);
  // −1 everywhere is the plain query.
  const std::vector<std::int32_t> none{-1, -1};
  own.vertex_ids = none.data();
  own.triangle_ids = none.data();
  tracer.ao(r.points(), r.normals(), own, opts(64), out.data());
  EXPECT_EQ(out, tracer.ao(r.points(), r.normals(), opts(64)));
}

// === Sample sets

// RMS error over many rows (each its own rotation / scramble) against the exact AO `want`.
double rms_error(const RayTracer& tracer, const Receivers& r, int samples, Sampling sampling,
                 double want) {
  RayTraceOptions o = opts(samples);
  o.sampling = sampling;
  double sum = 0;
  const auto ao = tracer.ao(r.points(), r.normals(), o);
  for (float v : ao) sum += (v - want) * (v - want);
  return std::sqrt(sum / static_cast<double>(ao.size()));
}

TEST(RayTracer, StratifiedSampleSetsBeatIndependentRays) {
  // Two closed forms: under the edge of a half-plane (AO 1/2) and below a sphere 30° off the
  // normal (1 − (r/d)² cos 30°). Independent rays have RMS error sqrt(a(1 − a)/N) (binomial);
  // over 2000 rows its estimate is within ±5 % (σ of an RMS over n rows ≈ RMS/sqrt(2n)). The
  // lattice and the Sobol' net must beat it by a clear margin. Measured, as a fraction of it at
  // 16 / 64 rays: lattice 0.33 / 0.21 (half-plane), 0.61 / 0.41 (sphere); Sobol' 0 (the
  // half-plane's edge splits every elementary interval evenly) and 0.77 / 0.50.
  const float r = 1, d = 4, th = 30 * kPi / 180;
  const Mesh roof = horizontal(0, 200, -200, 200, 1);
  const Mesh ball = uv_sphere({d * std::sin(th), 0, d * std::cos(th)}, r, 64, 128);
  const Receivers rows({0, 0, 0}, {0, 0, 1}, 2000);
  const struct {
    const Mesh* mesh;
    double want;
  } cases[] = {{&roof, 0.5}, {&ball, 1.0 - (r / d) * (r / d) * std::cos(th)}};
  for (const auto& c : cases) {
    const RayTracer tracer = c.mesh->tracer();
    for (int n : {16, 64}) {
      const double binomial = std::sqrt(c.want * (1 - c.want) / n);
      EXPECT_NEAR(rms_error(tracer, rows, n, Sampling::kIndependent, c.want), binomial,
                  0.1 * binomial) << n << " rays, AO " << c.want;
      const double bound = (n == 16 ? 0.85 : 0.6) * binomial;
      EXPECT_LT(rms_error(tracer, rows, n, Sampling::kLattice, c.want), bound)
          << n << " rays, AO " << c.want;
      EXPECT_LT(rms_error(tracer, rows, n, Sampling::kSobol, c.want), bound)
          << n << " rays, AO " << c.want;
    }
  }
}

TEST(RayTracer, EverySampleSetIsTheSameWhateverTheThreadCount) {
  const Mesh leaves = canopy(2000, 2, 0.25f, 5);
  const RayTracer tracer = leaves.tracer();
  const std::vector<float> nrm = random_normals(leaves.view().size, 9);
  const PointsView pts = leaves.view(), nv{nrm.data(), leaves.view().size};
  std::vector<std::int32_t> self(pts.size);
  std::iota(self.begin(), self.end(), 0);
  OwnPrimitives own;
  own.vertex_ids = self.data();
  for (Sampling sampling : {Sampling::kLattice, Sampling::kSobol, Sampling::kIndependent}) {
    RayTraceOptions o = opts(48, kInf, 3);
    o.sampling = sampling;
    std::vector<float> one(pts.size), two(pts.size);
    const int prev = set_max_threads(1);
    tracer.ao(pts, nv, own, o, one.data());
    set_max_threads(2);
    tracer.ao(pts, nv, own, o, two.data());
    set_max_threads(prev);
    EXPECT_EQ(one, two);
    // A point's answer depends on its row alone: the first 100 rows traced on their own.
    std::vector<float> part(100);
    tracer.ao({pts.data, 100}, {nv.data, 100}, own, o, part.data());
    EXPECT_TRUE(std::equal(part.begin(), part.end(), one.begin()));
  }
}

// === Instances

TEST(RayTracer, InstancesOccludeAsTheirFlattenedCopies) {
  // Three placed copies of a small "crown" (random leaves in a ball) over a ground plane,
  // rotated, scaled, one mirrored: the same AO as the same triangles written out, up to rays
  // grazing a triangle edge (float rounding of the transform): at most 2 of 256 rays per point.
  const Mesh crown = canopy(400, 1.0f, 0.3f, 21);
  Mesh ground = horizontal(-20, 20, -20, 20, 0);
  Mesh flat = ground;
  std::vector<Instance> placed(3);
  const float c30 = std::cos(kPi / 6), s30 = std::sin(kPi / 6);
  const float mats[3][12] = {{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 3},
                             {1.5f * c30, -1.5f * s30, 0, 4, 1.5f * s30, 1.5f * c30, 0, 1, 0, 0,
                              1.5f, 4},
                             {-0.8f, 0, 0, -3, 0, 0.8f, 0.2f, 2, 0, 0, 0.8f, 2.5f}};  // mirrored
  for (int k = 0; k < 3; ++k) {
    std::copy(mats[k], mats[k] + 12, placed[k].matrix);
    const float* a = mats[k];
    const std::int32_t base = static_cast<std::int32_t>(flat.v.size() / 3);
    for (std::size_t i = 0; i < crown.v.size(); i += 3) {
      const double x = crown.v[i], y = crown.v[i + 1], z = crown.v[i + 2];
      flat.add({static_cast<float>(a[0] * x + a[1] * y + a[2] * z + a[3]),
                static_cast<float>(a[4] * x + a[5] * y + a[6] * z + a[7]),
                static_cast<float>(a[8] * x + a[9] * y + a[10] * z + a[11])});
    }
    for (std::int32_t j : crown.t) flat.t.push_back(base + j);
  }
  const Prototype proto{crown.view(), crown.t.data(), crown.triangles()};
  const RayTracer instanced(ground.view(), ground.t.data(), ground.triangles(), {proto}, placed);
  EXPECT_EQ(instanced.instance_count(), 3u);
  EXPECT_EQ(instanced.triangle_count(), 2u);
  // Receivers on the ground under and between the crowns (normal up), and in the air facing
  // every way.
  std::vector<float> p, n;
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(-6, 6);
  for (int i = 0; i < 400; ++i) {
    const bool air = i % 2;
    p.insert(p.end(), {u(rng), u(rng), air ? 1.0f + std::fabs(u(rng)) : 0.0f});
    n.insert(n.end(), {air ? u(rng) : 0.0f, air ? u(rng) : 0.0f, air ? u(rng) : 1.0f});
  }
  const PointsView pv{p.data(), p.size() / 3}, nv{n.data(), n.size() / 3};
  const auto a = instanced.ao(pv, nv, opts(256, 30));
  const auto b = flat.tracer().ao(pv, nv, opts(256, 30));
  double worst = 0, sum = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, std::fabs(static_cast<double>(a[i]) - b[i]));
    sum += b[i];
  }
  EXPECT_LE(worst, 2.0 / 256);
  EXPECT_LT(sum / a.size(), 0.95);  // the crowns do occlude
  EXPECT_GT(sum / a.size(), 0.3);

  // Without its own mesh, instances alone still occlude.
  const RayTracer only(PointsView{nullptr, 0}, nullptr, 0, {proto}, placed);
  EXPECT_LT(mean(only.ao(pv, nv, opts(64, 30))), 0.99);
}

TEST(RayTracer, BadInstancesThrowInvalidArgument) {
  const Mesh crown = canopy(10, 1.0f, 0.3f, 2);
  const Mesh ground = horizontal(-1, 1, -1, 1, 0);
  const Prototype proto{crown.view(), crown.t.data(), crown.triangles()};
  std::vector<Instance> bad(1);
  bad[0].prototype = 1;
  EXPECT_THROW(RayTracer(ground.view(), ground.t.data(), 2, {proto}, bad), std::invalid_argument);
  bad[0].prototype = 0;
  bad[0].matrix[5] = std::nanf("");
  EXPECT_THROW(RayTracer(ground.view(), ground.t.data(), 2, {proto}, bad), std::invalid_argument);
  bad[0].matrix[5] = 1;
  bad[0].matrix[14] = 0.5f;  // projective
  EXPECT_THROW(RayTracer(ground.view(), ground.t.data(), 2, {proto}, bad), std::invalid_argument);
  Mesh broken = crown;
  broken.t[0] = 99;
  const Prototype bad_proto{broken.view(), broken.t.data(), broken.triangles()};
  EXPECT_THROW(RayTracer(ground.view(), ground.t.data(), 2, {bad_proto}, {}),
               std::invalid_argument);
}

// === Determinism

TEST(RayTracer, DeterministicWhateverTheThreadCount) {
  const Mesh leaves = canopy(2000, 2, 0.25f, 7);
  const RayTracer tracer = leaves.tracer();
  // Receivers on the leaves' own vertices, normals random (any direction is valid).
  const std::vector<float> nrm = random_normals(leaves.view().size, 3);
  const PointsView pts = leaves.view(), nv{nrm.data(), leaves.view().size};

  const int prev = set_max_threads(1);
  const auto one = tracer.ao(pts, nv, opts(64));
  set_max_threads(2);
  const auto two = tracer.ao(pts, nv, opts(64));
  set_max_threads(0);
  const auto all = tracer.ao(pts, nv, opts(64));
  set_max_threads(prev);
  EXPECT_EQ(one, two);
  EXPECT_EQ(one, all);
  EXPECT_EQ(one, tracer.ao(pts, nv, opts(64)));  // same seed, same bits

  // Another seed: other noise, same expectation (mean over 6k points: σ ≲ 0.001).
  const auto other = tracer.ao(pts, nv, opts(64, kInf, 12345));
  std::size_t differ = 0;
  for (std::size_t i = 0; i < one.size(); ++i) differ += one[i] != other[i];
  EXPECT_GT(differ, one.size() / 4);
  EXPECT_NEAR(mean(one), mean(other), 0.005);
  EXPECT_GT(mean(one), 0.05);  // a real canopy: neither empty nor sealed
  EXPECT_LT(mean(one), 0.95);
}

TEST(RayTracer, BvhBuiltOnOneOrTwoThreadsGivesTheSameAnswer) {
  // Occlusion is an any-hit test: each triangle's test does not depend on the tree, so even a
  // BVH built differently under another thread cap must give the same bits.
  const Mesh leaves = canopy(3000, 2, 0.25f, 11);
  const Receivers r({0.1f, 0.2f, 0.3f}, {1, 0, 0}, 64);
  const int prev = set_max_threads(1);
  const auto one = ao_raytrace(leaves.view(), leaves.t.data(), leaves.triangles(), r.points(),
                               r.normals(), opts(64));
  set_max_threads(2);
  const auto two = ao_raytrace(leaves.view(), leaves.t.data(), leaves.triangles(), r.points(),
                               r.normals(), opts(64));
  set_max_threads(prev);
  EXPECT_EQ(one, two);
}

TEST(RayTracer, OneOffFunctionMatchesTheReusableTracer) {
  const Mesh leaves = canopy(500, 1, 0.3f, 1);
  const Receivers r({0, 0, 0}, {0, 1, 0}, 8);
  const auto a = ao_raytrace(leaves.view(), leaves.t.data(), leaves.triangles(), r.points(),
                             r.normals(), opts(128));
  EXPECT_EQ(a, leaves.tracer().ao(r.points(), r.normals(), opts(128)));
}

TEST(RayTracer, HighQualityAndRobustBuildsGiveTheSameAnswer) {
  // Rays grazing the roof's edge right above the receiver may go either way: one ray per
  // point at most.
  const Mesh roof = horizontal(0, 200, -200, 200, 1);
  const Receivers r({0, 0, 0}, {0, 0, 1}, 16);
  RayTracerBuildOptions b;
  b.high_quality = true;
  b.robust = true;
  const RayTracer t(roof.view(), roof.t.data(), roof.triangles(), b);
  const auto robust = t.ao(r.points(), r.normals(), opts(256));
  const auto fast = roof.tracer().ao(r.points(), r.normals(), opts(256));
  for (std::size_t i = 0; i < r.points().size; ++i) EXPECT_NEAR(robust[i], fast[i], 1.01 / 256);
}

// === Edge cases and bad input

TEST(RayTracer, EmptyMeshIsOpenSky) {
  const Receivers r({1, 2, 3}, {0, 0, 1}, 4);
  const RayTracer nothing(PointsView{nullptr, 0}, nullptr, 0);
  for (float v : nothing.ao(r.points(), r.normals())) EXPECT_EQ(v, 1.0f);
  const Mesh loose = [] {
    Mesh m;
    m.add({0, 0, 1});
    m.add({1, 0, 1});
    return m;
  }();
  for (float v : loose.tracer().ao(r.points(), r.normals())) EXPECT_EQ(v, 1.0f);
  EXPECT_TRUE(nothing.ao(PointsView{nullptr, 0}, PointsView{nullptr, 0}).empty());
}

TEST(RayTracer, ZeroNormalIsOneAndUnnormalisedNormalsAreNormalised) {
  const RayTracer tracer = cube(1).tracer();
  const Receivers zero({0, 0, 0}, {0, 0, 0}, 2);
  for (float v : tracer.ao(zero.points(), zero.normals())) EXPECT_EQ(v, 1.0f);
  const Mesh roof = horizontal(0, 200, -200, 200, 1);
  const Receivers unit({0, 0, 0}, {0, 0, 1}, 8), longer({0, 0, 0}, {0, 0, 5}, 8),
      tiny({0, 0, 0}, {0, 0, 1e-30f}, 8);
  const auto want = roof.tracer().ao(unit.points(), unit.normals());
  EXPECT_EQ(want, roof.tracer().ao(longer.points(), longer.normals()));
  EXPECT_EQ(want, roof.tracer().ao(tiny.points(), tiny.normals()));  // no underflow to "zero"
}

TEST(RayTracer, BadInputThrowsInvalidArgument) {
  const Mesh box = cube(1);
  const RayTracer tracer = box.tracer();
  const Receivers r({0, 0, 0}, {0, 0, 1}, 2);
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), opts(0)), std::invalid_argument);
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), opts(-3)), std::invalid_argument);
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), opts(8, 0)), std::invalid_argument);
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), opts(8, -1)), std::invalid_argument);
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), opts(8, std::nanf(""))), std::invalid_argument);
  RayTraceOptions bad_offset;
  bad_offset.offset = std::nanf("");
  EXPECT_THROW(tracer.ao(r.points(), r.normals(), bad_offset), std::invalid_argument);

  const Receivers nan_point({std::nanf(""), 0, 0}, {0, 0, 1}, 1);
  EXPECT_THROW(tracer.ao(nan_point.points(), nan_point.normals()), std::invalid_argument);
  const Receivers inf_normal({0, 0, 0}, {0, kInf, 1}, 1);
  EXPECT_THROW(tracer.ao(inf_normal.points(), inf_normal.normals()), std::invalid_argument);
  const Receivers three({0, 0, 0}, {0, 0, 1}, 3);
  EXPECT_THROW(tracer.ao(r.points(), three.normals()), std::invalid_argument);
  EXPECT_THROW(tracer.ao_at_vertices(r.normals()), std::invalid_argument);

  Mesh out_of_range = box;
  out_of_range.t[5] = 8;
  EXPECT_THROW(out_of_range.tracer(), std::invalid_argument);
  out_of_range.t[5] = -1;
  EXPECT_THROW(out_of_range.tracer(), std::invalid_argument);
  Mesh nan_vertex = box;
  nan_vertex.v[4] = std::nanf("");
  EXPECT_THROW(nan_vertex.tracer(), std::invalid_argument);
  EXPECT_THROW(ao_raytrace(box.view(), box.t.data(), box.triangles(), r.points(), r.normals(),
                           opts(0)),
               std::invalid_argument);
}

// === Cycles' bake point (raytrace.h, "Origins"): expected values are Cycles' own vertex bakes
// (Blender 3.4, 1024 samples; bench/probes/cycles_contact_probe.py and bench/cycles_contact.py).

namespace {

// AO at vertex `v` of m, as the add-on asks: the vertex its own receiver, 1024 rays.
float vertex_ao(const RayTracer& tracer, const Mesh& m, std::int32_t v, Vec3 n,
                float distance = kInf) {
  const Receivers r(m.view()[static_cast<std::size_t>(v)], n, 1);
  const std::vector<std::int32_t> vid(1, v);
  OwnPrimitives own;
  own.vertex_ids = vid.data();
  float out = -1;
  tracer.ao(r.points(), r.normals(), own, opts(1024, distance), &out);
  return out;
}

// A right triangle of legs L from `o` (normal +z) under a roof quad h above it, covering the
// triangle's square from (o + s, o + s) on: whether vertex 0 is under the roof depends on where
// its bake point lies.
Mesh triangle_under_roof(Vec3 o, float L, float s, float h) {
  Mesh m;
  const std::int32_t a = m.add(o), b = m.add(o + Vec3{L, 0, 0}), c = m.add(o + Vec3{0, L, 0});
  m.tri(a, b, c);
  m.quad(o + Vec3{s, s, h}, o + Vec3{L, s, h}, o + Vec3{L, L, h}, o + Vec3{s, L, h});
  return m;
}

}  // namespace

TEST(BakePoint, StartsWhereCyclesBakesAVertexNotAtIt) {
  // Cycles moves a vertex's bake point 1e-4 × max(1, |x|max) towards the triangle's centroid:
  // 1.8 mm at x = 18, so a 1 cm triangle's corner bakes under a roof 10 µm up that starts 1 mm
  // inside (Cycles 0.001), and not under one that starts 3 mm inside (x = 21: 2.1 mm; Cycles
  // 1.000). The own-surface rule starts a hair from the vertex: open in both.
  const float L = 0.01f, h = 1e-5f;
  const Mesh near_roof = triangle_under_roof({18, 0, 0}, L, 0.1f * L, h);
  const Mesh far_roof = triangle_under_roof({21, 0, 0}, L, 0.3f * L, h);
  const Vec3 up{0, 0, 1};
  EXPECT_LT(vertex_ao(near_roof.baking(same_normals(near_roof, up)), near_roof, 0, up), 0.05f);
  EXPECT_GT(vertex_ao(far_roof.baking(same_normals(far_roof, up)), far_roof, 0, up), 0.95f);
  EXPECT_GT(vertex_ao(near_roof.tracer(), near_roof, 0, up), 0.9f);
}

TEST(BakePoint, ASmoothLowPolyTubeIsOpenAsInCycles) {
  // An isolated square tube, smooth-shaded (vertex normals 45° off every face), 12 m from the
  // origin: Cycles bakes 1.000 at every vertex. From a start inside a face about a seventh of
  // the hemisphere dives into the tube; Cycles' terminator lift takes those rays off the face.
  Mesh m;
  std::vector<float> normals;
  const float w = 0.0022f, len = 0.05f;
  const Vec3 base{3, 3, 11};
  for (int r = 0; r < 5; ++r) {
    for (int k = 0; k < 4; ++k) {
      const float x = (k == 1 || k == 2) ? w / 2 : -w / 2, y = k >= 2 ? w / 2 : -w / 2;
      m.add(base + Vec3{x, y, len * r / 4});
      const Vec3 n = normalize(Vec3{x, y, 0});
      normals.insert(normals.end(), {n.x, n.y, n.z});
    }
  }
  for (int r = 0; r < 4; ++r) {
    for (int k = 0; k < 4; ++k) {
      const std::int32_t a = 4 * r + k, b = 4 * r + (k + 1) % 4;
      m.tri(a, b, b + 4);
      m.tri(a, b + 4, a + 4);
    }
  }
  const RayTracer tracer = m.baking(normals);
  for (std::int32_t v = 8; v < 12; ++v) {
    const Vec3 n{normals[3 * v], normals[3 * v + 1], normals[3 * v + 2]};
    EXPECT_GT(vertex_ao(tracer, m, v, n), 0.99f) << "mid-ring vertex " << v;
  }
}

TEST(BakePoint, AStartInAnotherFacesPlaneSeesThatFace) {
  // A 2 mm quad lying in a larger quad's plane (gap 0): Cycles bakes its vertices 0 (its ROBUST
  // hit test counts the face through the start), near the origin and 10 m away alike.
  for (const Vec3 o : {Vec3{0, 0, 0.001f}, Vec3{3, 3, 10}}) {
    Mesh m = horizontal(o.x - 0.1f, o.x + 0.1f, o.y - 0.1f, o.y + 0.1f, o.z);
    m.quad(o, o + Vec3{0.002f, 0, 0}, o + Vec3{0.002f, 0.002f, 0}, o + Vec3{0, 0.002f, 0});
    const Vec3 up{0, 0, 1};
    const RayTracer tracer = m.baking(same_normals(m, up));
    for (std::int32_t v = 4; v < 8; ++v) EXPECT_LT(vertex_ao(tracer, m, v, up, 0.5f), 0.01f);
  }
}

TEST(BakePoint, BladeRootsOnTheGroundAgreeWithCyclesAndTheClosedForm) {
  // bench/cycles_contact.py's blades standing on a 100 m ground, upright or leaning 25° either
  // way: roots (1 + n·up)/2, Cycles 0.500, 0.710, 0.289. (Its capped trunk, whose bottom cap
  // lies in the ground, needs Blender's own mesh and normals: bench/cycles_contact.py prints
  // 0.120 against Cycles' 0.129.)
  Mesh m = horizontal(-50, 50, -50, 50, 0);
  std::vector<float> normals = same_normals(m, {0, 0, 1});
  std::vector<std::int32_t> roots;
  std::vector<Vec3> root_normals;
  for (int k = 0; k < 3; ++k) {
    const float beta = (k == 0 ? 0.0f : (k == 1 ? 25.0f : -25.0f)) * kPi / 180;
    const float x = 0.37f + 3 * k, y = 0.23f;
    const Vec3 up{0, std::sin(beta), std::cos(beta)};
    const Vec3 n{0, -std::cos(beta), std::sin(beta)};  // Blender's normal for this winding
    const std::int32_t a = m.add({x - 0.01f, y, 0}), b = m.add({x + 0.01f, y, 0});
    const std::int32_t c = m.add(Vec3{x + 0.01f, y, 0} + 0.3f * up);
    const std::int32_t d = m.add(Vec3{x - 0.01f, y, 0} + 0.3f * up);
    m.tri(a, b, c);
    m.tri(a, c, d);
    for (int i = 0; i < 4; ++i) normals.insert(normals.end(), {n.x, n.y, n.z});
    roots.insert(roots.end(), {a, b});
    root_normals.insert(root_normals.end(), {n, n});
  }
  const RayTracer tracer = m.baking(normals);
  const float want_roots[3] = {0.500f, 0.710f, 0.289f};
  for (int k = 0; k < 3; ++k) {
    for (int j = 0; j < 2; ++j) {
      const Vec3 n = root_normals[2 * k + j];
      EXPECT_NEAR(vertex_ao(tracer, m, roots[2 * k + j], n, 20), want_roots[k], 0.01)
          << "blade " << k;
    }
  }
}

TEST(BakePoint, OnePolygonIsOneCorner) {
  // A quad whose two triangles both use vertex 0 (its diagonal): Blender bakes that corner
  // once, on the first triangle.
  Mesh m;
  const Vec3 o{0, 0, 0};
  const float L = 0.01f;
  const std::int32_t a = m.add(o), b = m.add({L, 0, 0}), c = m.add({L, L, 0}), d = m.add({0, L, 0});
  m.tri(a, b, c);  // centroid below the diagonal (y < x)
  m.tri(a, c, d);  // centroid above it
  // A 40 µm roof 1 µm over the second triangle's bake point (0.1 mm from the vertex towards
  // that triangle's centroid): it shades that bake point almost whole, the first one hardly.
  const Vec3 p2 = 1e-4f * normalize(Vec3{1, 2, 0});
  const float r = 2e-5f, z = 1e-6f;
  m.quad(p2 + Vec3{-r, -r, z}, p2 + Vec3{r, -r, z}, p2 + Vec3{r, r, z}, p2 + Vec3{-r, r, z});
  const std::vector<float> up = same_normals(m, {0, 0, 1});
  const std::vector<std::int32_t> one_quad = {0, 0, 1, 1};
  const float per_triangle = vertex_ao(m.baking(up), m, a, {0, 0, 1});
  const float per_polygon = vertex_ao(m.baking(up, &one_quad), m, a, {0, 0, 1});
  EXPECT_GT(per_polygon, 0.95f);  // only the first triangle's bake point: open
  EXPECT_NEAR(per_triangle, 0.5f, 0.05f);  // half its rays from the roofed bake point
}

namespace {

// A flat hexagonal fan of unit radius around vertex 0 (six triangles, normal +z).
Mesh hexagon_fan() {
  Mesh m;
  m.add({0, 0, 0});
  for (int k = 0; k < 6; ++k) {
    const float a = 2.0f * 3.14159265f * static_cast<float>(k) / 6.0f;
    m.add({std::cos(a), std::sin(a), 0});
  }
  for (int k = 0; k < 6; ++k) m.tri(0, 1 + k, 1 + (k + 1) % 6);
  return m;
}

}  // namespace

TEST(BakePoint, EveryCornerCastsTheFullSampleCount) {
  // Cycles bakes every face corner with its sample count; so do we (per_corner): a vertex of k
  // corners casts the k × S rays that dealing k × S out to its corners casts, the same
  // directions (so bit-identical AO), and its AO is a multiple of 1 / (k × S).
  Mesh m = hexagon_fan();
  m.quad({-0.2f, -0.3f, 0.15f}, {0.6f, -0.3f, 0.15f}, {0.6f, 0.5f, 0.15f}, {-0.2f, 0.5f, 0.15f});
  const std::vector<float> up = same_normals(m, {0, 0, 1});
  const RayTracer tracer = m.baking(up);
  const int S = 8;
  for (std::int32_t v = 0; v < 7; ++v) {
    const int k = v == 0 ? 6 : 2;  // the hub uses six triangles, a rim vertex two
    const Receivers r(m.view()[static_cast<std::size_t>(v)], {0, 0, 1}, 1);
    OwnPrimitives own;
    own.vertex_ids = &v;
    RayTraceOptions per_corner = opts(S), dealt = opts(S * k);
    dealt.per_corner = false;
    float a = -1, b = -1;
    tracer.ao(r.points(), r.normals(), own, per_corner, &a);
    tracer.ao(r.points(), r.normals(), own, dealt, &b);
    EXPECT_EQ(a, b) << "vertex " << v;
    const float rays = a * static_cast<float>(S * k);
    EXPECT_NEAR(rays, std::round(rays), 1e-3f) << "vertex " << v;
    if (v == 0) {  // the roof covers the hub: some rays blocked, not all
      EXPECT_GT(a, 0.05f);
      EXPECT_LT(a, 0.95f);
      RayTraceOptions dealt_s = opts(S);
      dealt_s.per_corner = false;
      float c = -1;
      tracer.ao(r.points(), r.normals(), own, dealt_s, &c);
      const float dealt_rays = c * static_cast<float>(S);
      EXPECT_NEAR(dealt_rays, std::round(dealt_rays), 1e-3f);
    }
  }
  // A receiver that is not a vertex (no corners) casts S either way.
  const Receivers free_point({0.1f, 0.1f, 0.05f}, {0, 0, 1}, 1);
  RayTraceOptions dealt = opts(S);
  dealt.per_corner = false;
  EXPECT_EQ(tracer.ao(free_point.points(), free_point.normals(), opts(S)),
            tracer.ao(free_point.points(), free_point.normals(), dealt));
}

TEST(BakePoint, EachPointCastsItsOwnSampleCount) {
  // point_samples: a point's count in place of `samples`, each point as if traced alone at it
  // (the add-on spreads Cycles' rays evenly: a count per vertex, dealt out to its corners).
  Mesh m = hexagon_fan();
  m.quad({-0.2f, -0.3f, 0.15f}, {0.6f, -0.3f, 0.15f}, {0.6f, 0.5f, 0.15f}, {-0.2f, 0.5f, 0.15f});
  const std::vector<float> up = same_normals(m, {0, 0, 1});
  const RayTracer tracer = m.baking(up);
  std::vector<std::int32_t> ids = {0, 1, 2, 0};
  std::vector<float> pts, nrm;
  for (std::int32_t v : ids) {
    const Vec3 x = m.view()[static_cast<std::size_t>(v)];
    pts.insert(pts.end(), {x.x, x.y, x.z});
    nrm.insert(nrm.end(), {0.0f, 0.0f, 1.0f});
  }
  const PointsView p{pts.data(), ids.size()}, n{nrm.data(), ids.size()};
  OwnPrimitives own;
  own.vertex_ids = ids.data();
  const std::vector<std::int32_t> counts = {12, 6, 24, 48};
  for (const bool per_corner : {true, false}) {
    RayTraceOptions each = opts(8);
    each.per_corner = per_corner;
    each.point_samples = counts.data();
    std::vector<float> got(ids.size(), -1.0f);
    tracer.ao(p, n, own, each, got.data());
    for (std::size_t i = 0; i < ids.size(); ++i) {
      RayTraceOptions alone = opts(counts[i]);
      alone.per_corner = per_corner;
      std::vector<float> want(ids.size(), -1.0f);
      tracer.ao(p, n, own, alone, want.data());
      EXPECT_EQ(got[i], want[i]) << "point " << i << (per_corner ? " per corner" : " dealt");
    }
    if (per_corner) {  // the hub (under the roof) at 12 and at 48: other rays, other AO
      EXPECT_NE(got[0], got[3]);
      EXPECT_GT(got[0], 0.05f);
      EXPECT_LT(got[0], 0.95f);
    }
  }
  const std::vector<std::int32_t> bad = {12, 0, 24, 48};
  RayTraceOptions zero = opts(8);
  zero.point_samples = bad.data();
  std::vector<float> out(ids.size());
  EXPECT_THROW(tracer.ao(p, n, own, zero, out.data()), std::invalid_argument);
}

TEST(BakePoint, TexelSubSamplesShareOneDealtSet) {
  // point_group: g consecutive texel points share one set of directions keyed by the group,
  // point j casting rays j, j + g, ...: g points at one spot average to that spot's estimate
  // at the group's count, ray for ray (the first group is keyed as row 0 alone).
  Mesh m = hexagon_fan();
  m.quad({-0.2f, -0.3f, 0.15f}, {0.6f, -0.3f, 0.15f}, {0.6f, 0.5f, 0.15f}, {-0.2f, 0.5f, 0.15f});
  const std::vector<float> up = same_normals(m, {0, 0, 1});
  const RayTracer tracer = m.baking(up);
  constexpr std::size_t kG = 4;
  const Vec3 a = m.view()[0], b = m.view()[1], c = m.view()[2];  // triangle 0, the hub's
  const Vec3 x = (a * 2.0f + b + c) / 4.0f;  // inside it, under the roof's edge
  std::vector<float> pts, nrm;
  for (std::size_t i = 0; i < 2 * kG; ++i) {
    pts.insert(pts.end(), {x.x, x.y, x.z});
    nrm.insert(nrm.end(), {0.0f, 0.0f, 1.0f});
  }
  const std::vector<std::int32_t> tri(2 * kG, 0);
  OwnPrimitives own;
  own.triangle_ids = tri.data();
  const PointsView p{pts.data(), 2 * kG}, n{nrm.data(), 2 * kG};
  RayTraceOptions grouped = opts(64);
  grouped.point_group = static_cast<int>(kG);
  std::vector<float> got(2 * kG, -1.0f), alone(1, -1.0f);
  tracer.ao(p, n, own, grouped, got.data());
  tracer.ao(PointsView{pts.data(), 1}, PointsView{nrm.data(), 1}, own, opts(64), alone.data());
  float mean = 0.0f;
  for (std::size_t i = 0; i < kG; ++i) mean += got[i];
  EXPECT_EQ(mean / kG, alone[0]);
  EXPECT_GT(alone[0], 0.05f);
  EXPECT_LT(alone[0], 0.95f);
  for (std::size_t i = 0; i < 2 * kG; ++i) {  // 16 rays each: multiples of 1/16
    EXPECT_NEAR(got[i] * 16.0f, std::round(got[i] * 16.0f), 1e-4f) << "point " << i;
  }
  RayTraceOptions none = opts(64);
  none.point_group = 0;
  EXPECT_THROW(tracer.ao(p, n, own, none, got.data()), std::invalid_argument);
}

TEST(BakePoint, CornersPerVertexCountsFacesWithArea) {
  const Mesh fan = hexagon_fan();
  const std::vector<float> up = same_normals(fan, {0, 0, 1});
  // By triangles: the hub 6, each rim vertex 2: 18 / 7.
  EXPECT_NEAR(fan.baking(up).corners_per_vertex(), 18.0 / 7.0, 1e-12);
  // Triangles paired into three quads: the hub 3, rim vertices 1 (inside a quad) or 2: 12 / 7.
  const std::vector<std::int32_t> quads = {0, 0, 1, 1, 2, 2};
  EXPECT_NEAR(fan.baking(up, &quads).corners_per_vertex(), 12.0 / 7.0, 1e-12);
  // Without vertex normals there is no bake point: one start per receiver.
  EXPECT_EQ(fan.tracer().corners_per_vertex(), 1.0);
  // A triangle of zero area is a corner: Cycles' face normal there is its fused cross
  // product's rounding residue, here exactly 0 (collinear on an axis, every product exact), so
  // NaN, and the corner is open (raytrace.h, 'Origins'); an unused vertex counts one.
  Mesh sliver;
  for (const Vec3 p : {Vec3{0, 0, 0}, Vec3{1, 0, 0}, Vec3{2, 0, 0}, Vec3{0, 1, 0},
                       Vec3{-1, 0, 0}, Vec3{5, 5, 5}}) {
    sliver.add(p);  // the last one used by no triangle
  }
  sliver.tri(0, 1, 2);  // zero area
  sliver.tri(0, 1, 3);
  sliver.tri(0, 3, 4);
  // 0: 3 corners, 1: 2, 2: 1, 3: 2, 4: 1, 5: unused (1): 10 / 6.
  EXPECT_NEAR(sliver.baking(same_normals(sliver, {0, 0, 1})).corners_per_vertex(), 10.0 / 6.0,
              1e-12);
}

TEST(BakePoint, VertexRaysCountWhatABakeCasts) {
  const Mesh fan = hexagon_fan();
  const RayTracer baking = fan.baking(same_normals(fan, {0, 0, 1}));
  // The hub (vertex 0) has 6 corners, each rim vertex 2: the cost model's counted rays.
  EXPECT_EQ(baking.vertex_rays(0, 7, 16), 18u * 16u);
  EXPECT_EQ(baking.vertex_rays(1, 2, 16), 4u * 16u);
  EXPECT_EQ(baking.vertex_rays(3, 0, 16), 0u);
  // At most max(samples, 65,536) rays per vertex, as RayTracer::ao casts.
  EXPECT_EQ(baking.vertex_rays(0, 1, 20000), 65536u);
  EXPECT_EQ(baking.vertex_rays(0, 1, 70000), 70000u);
  EXPECT_EQ(fan.tracer().vertex_rays(0, 7, 16), 7u * 16u);  // no bake point: one start each
  EXPECT_THROW(baking.vertex_rays(5, 3, 16), std::invalid_argument);
  EXPECT_THROW(baking.vertex_rays(0, 1, 0), std::invalid_argument);
}

TEST(BakePoint, AVertexWithOnlyZeroAreaFacesStartsOffItsPoint) {
  // A branch tip collapsed to a point (Sapling's tapering to radius 0): the tip vertex's own
  // faces have zero area, and a cone's faces meet at the same point through another vertex.
  // From the point itself every ray hits a cone face at t = 0 (the scene is ROBUST): AO 0. The
  // tip starts 1e-4 × max(1, |x|max) off along its normal, so looking up it sees the sky.
  Mesh m;
  const Vec3 tip{3, 2, 12};
  const std::int32_t v = m.add(tip), w = m.add(tip), below = m.add(tip - Vec3{0, 0, 0.1f});
  m.tri(below, v, w);  // zero area: two of its corners coincide
  const std::int32_t apex = m.add(tip);
  std::int32_t ring[6];
  for (int k = 0; k < 6; ++k) {
    const float a = 2.0f * 3.14159265f * static_cast<float>(k) / 6.0f;
    ring[k] = m.add(tip + Vec3{0.02f * std::cos(a), 0.02f * std::sin(a), -0.3f});
  }
  for (int k = 0; k < 6; ++k) m.tri(ring[k], ring[(k + 1) % 6], apex);
  std::vector<float> normals = same_normals(m, {0, 0, 1});
  const RayTracer tracer = m.baking(normals);
  EXPECT_GT(vertex_ao(tracer, m, v, {0, 0, 1}), 0.95f);
}

TEST(BakePoint, ACornerWithoutAFaceNormalIsOpen) {
  // Inside a closed cube every traced ray is blocked. Vertex p's second triangle starts with
  // two coincident vertices (an edge of length 0 from its first one): Cycles' face normal there
  // is NaN and so is every ray direction, which nothing stops; that corner reads 1.0, so p
  // reads 1/2. Vertex q's second triangle has a zero edge between its last two vertices only,
  // where Cycles' face normal is its fused cross product's rounding residue; here every product
  // is exact, the residue 0 and the normal NaN again: q reads 1/2 too.
  Mesh m = cube(1.0f);
  const std::int32_t p = m.add({0, 0, 0}), a = m.add({0.1f, 0, 0}), b = m.add({0, 0.1f, 0});
  const std::int32_t c = m.add({-0.1f, 0, 0}), c2 = m.add({-0.1f, 0, 0});
  m.tri(p, a, b);
  m.tri(c, c2, p);
  const std::int32_t q = m.add({0.5f, 0.5f, 0}), e = m.add({0.6f, 0.5f, 0}),
                     f = m.add({0.5f, 0.6f, 0}), g = m.add({0.4f, 0.5f, 0}),
                     g2 = m.add({0.4f, 0.5f, 0});
  m.tri(q, e, f);
  m.tri(q, g, g2);
  const RayTracer tracer = m.baking(same_normals(m, {0, 0, 1}));
  EXPECT_EQ(vertex_ao(tracer, m, p, {0, 0, 1}), 0.5f);
  EXPECT_EQ(vertex_ao(tracer, m, q, {0, 0, 1}), 0.5f);
  EXPECT_EQ(vertex_ao(tracer, m, c, {0, 0, 1}), 1.0f);  // its one corner is the open one
  EXPECT_EQ(tracer.vertex_rays(static_cast<std::size_t>(p), 1, 16), 2u * 16u);  // both cast
  EXPECT_EQ(tracer.vertex_rays(static_cast<std::size_t>(q), 1, 16), 2u * 16u);
}

TEST(BakePoint, ACornerIsBakedOnTheTriangleBlendersBakeSplitsItsQuadInto) {
  // A quad B T1 T0 A whose T1 and T0 coincide (a branch tip Sapling collapses), given as the
  // mesh's cached triangulation splits it, (B T1 A)(T1 T0 A), which Blender's quad-flip test
  // with the face normal chooses. The bake triangulates again without the normal: (B T1 T0)
  // (B T0 A). Corner A is the bake's second triangle's slot 2, so Cycles bakes it on the
  // tracer's second triangle, (T1 T0 A), which has a NaN face normal: A reads 1.0 inside a
  // closed cube, where the first-triangle rule read 0. B stays on the first triangle: 0.
  Mesh m = cube(1.0f);
  const std::int32_t B = m.add({0, 0, 0}), T1 = m.add({0.1f, 0.05f, 0}),
                     T0 = m.add({0.1f, 0.05f, 0}), A = m.add({0, 0.1f, 0});
  m.tri(B, T1, A);
  m.tri(T1, T0, A);
  std::vector<std::int32_t> polys(m.triangles());
  for (std::size_t k = 0; k < polys.size(); ++k) polys[k] = static_cast<std::int32_t>(k);
  polys[polys.size() - 1] = polys[polys.size() - 2];  // the quad's two triangles: one face
  const RayTracer tracer = m.baking(same_normals(m, {0, 0, 1}), &polys);
  EXPECT_EQ(vertex_ao(tracer, m, A, {0, 0, 1}), 1.0f);
  EXPECT_EQ(vertex_ao(tracer, m, B, {0, 0, 1}), 0.0f);
  EXPECT_EQ(vertex_ao(tracer, m, T0, {0, 0, 1}), 0.0f);  // baked at A's point, traced: blocked
}

// Each triangle corner's normal, packed as BakeShading::corner_normals: corner j of triangle i
// takes normals[t[3i + j]] (the vertex's own), or `face` where given.
std::vector<float> corner_normals_of(const Mesh& m, const std::vector<float>& normals,
                                     const Vec3* face = nullptr) {
  std::vector<float> out;
  for (const std::int32_t v : m.t) {
    const float* q = normals.data() + 3 * static_cast<std::size_t>(v);
    out.insert(out.end(), face ? std::initializer_list<float>{face->x, face->y, face->z}
                               : std::initializer_list<float>{q[0], q[1], q[2]});
  }
  return out;
}

// Every vertex's AO on a tracer built with `corners` (null: none), 256 samples per corner.
std::vector<float> all_vertex_ao(const Mesh& m, const std::vector<float>& normals,
                                 const float* corners) {
  BakeShading shading;
  shading.vertex_normals = {normals.data(), normals.size() / 3};
  shading.corner_normals = corners;
  const RayTracer tracer(m.view(), m.t.data(), m.triangles(), shading, {}, {});
  std::vector<std::int32_t> vid(m.v.size() / 3);
  std::iota(vid.begin(), vid.end(), 0);
  OwnPrimitives own;
  own.vertex_ids = vid.data();
  std::vector<float> out(vid.size(), -1.0f);
  tracer.ao(m.view(), {normals.data(), normals.size() / 3}, own, opts(256), out.data());
  return out;
}

TEST(RayTracerCornerNormals, EqualToTheVertexNormalsTheAoIsBitIdentical) {
  // A smooth sphere resting on a ground quad: every corner normal its vertex's.
  Mesh m = uv_sphere({0, 0, 1.02f}, 1, 12, 16);
  std::vector<float> normals;
  for (std::size_t i = 0; i < m.v.size() / 3; ++i) {
    const Vec3 d = normalize(m.view()[i] - Vec3{0, 0, 1.02f});
    normals.insert(normals.end(), {d.x, d.y, d.z});
  }
  const auto base = static_cast<std::int32_t>(m.v.size() / 3);
  m.quad({-3, -3, 0}, {3, -3, 0}, {3, 3, 0}, {-3, 3, 0});
  for (int k = 0; k < 4; ++k) normals.insert(normals.end(), {0, 0, 1});
  ASSERT_EQ(static_cast<std::int32_t>(m.v.size() / 3), base + 4);
  const std::vector<float> corners = corner_normals_of(m, normals);
  const std::vector<float> without = all_vertex_ao(m, normals, nullptr);
  const std::vector<float> with = all_vertex_ao(m, normals, corners.data());
  ASSERT_EQ(with.size(), without.size());
  for (std::size_t v = 0; v < with.size(); ++v) EXPECT_EQ(with[v], without[v]) << "vertex " << v;
}

TEST(RayTracerCornerNormals, EachCornerTurnsAroundItsOwnNormal) {
  // A flat quad under a roof whose vertex normals lean towards the open side (a flat-shaded
  // face of a rock): with the face normal as its corners' normals it bakes as a quad whose
  // vertex normals are the face's, as Cycles bakes a flat face.
  Mesh m = horizontal(0, 1, 0, 1, 0);
  const Mesh roof = horizontal(-1, 1.05f, -1, 2, 0.3f, true);
  for (std::size_t i = 0; i < roof.v.size() / 3; ++i) m.add(roof.view()[i]);
  m.tri(4, 6, 5);
  m.tri(4, 7, 6);
  const Vec3 up{0, 0, 1}, lean = normalize(Vec3{1, 0, 0.3f});
  const std::vector<float> flat = same_normals(m, up), leaning = same_normals(m, lean);
  const std::vector<float> faces = corner_normals_of(m, leaning, &up);
  const std::vector<float> want = all_vertex_ao(m, flat, nullptr);
  const std::vector<float> got = all_vertex_ao(m, leaning, faces.data());
  const std::vector<float> vertex_only = all_vertex_ao(m, leaning, nullptr);
  for (std::size_t v = 0; v < 4; ++v) {
    EXPECT_EQ(got[v], want[v]) << "vertex " << v;
    // Leaning towards the open side, the vertex normals see more sky: a different bake.
    EXPECT_GT(vertex_only[v], want[v] + 0.05f) << "vertex " << v;
  }
}

TEST(RayTracerCornerNormals, BadCornerNormalsThrowInvalidArgument) {
  const Mesh m = horizontal(-1, 1, -1, 1, 0);
  const std::vector<float> normals = same_normals(m, {0, 0, 1});
  std::vector<float> corners = corner_normals_of(m, normals);
  BakeShading no_normals;
  no_normals.corner_normals = corners.data();
  EXPECT_THROW(RayTracer(m.view(), m.t.data(), m.triangles(), no_normals, {}, {}),
               std::invalid_argument);
  corners[7] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(all_vertex_ao(m, normals, corners.data()), std::invalid_argument);
}

TEST(BakePoint, BadShadingThrowsInvalidArgument) {
  const Mesh m = horizontal(-1, 1, -1, 1, 0);
  std::vector<float> short_normals(3 * 3, 0.0f), nan_normals = same_normals(m, {0, 0, 1});
  nan_normals[4] = std::numeric_limits<float>::quiet_NaN();
  const std::vector<std::int32_t> polys = {0, 0};
  EXPECT_THROW(m.baking(short_normals), std::invalid_argument);
  EXPECT_THROW(m.baking(nan_normals), std::invalid_argument);
  BakeShading no_normals;
  no_normals.polygons = polys.data();
  EXPECT_THROW(RayTracer(m.view(), m.t.data(), m.triangles(), no_normals, {}, {}),
               std::invalid_argument);
}
