// Tests of the leaf-density grid (density_grid.h).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <vector>

#include "canopy_ao/density_grid.h"
#include "canopy_ao/medium_table.h"
#include "canopy_ao/occlusion_features.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"

using namespace canopy_ao;

namespace {

constexpr float kPi = 3.14159265358979f;

struct Rng {  // splitmix64: deterministic on every platform
  std::uint64_t s;
  explicit Rng(std::uint64_t seed) : s(seed) {}
  float uniform() {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return static_cast<float>(z >> 40) * (1.0f / (1 << 24));
  }
  Vec3 unit() {
    const float z = 2 * uniform() - 1, p = 2 * kPi * uniform(), r = std::sqrt(1 - z * z);
    return {r * std::cos(p), r * std::sin(p), z};
  }
  Vec3 in_ball() {
    for (;;) {
      const Vec3 p{2 * uniform() - 1, 2 * uniform() - 1, 2 * uniform() - 1};
      if (dot(p, p) <= 1) return p;
    }
  }
};

struct Mesh {
  std::vector<float> v;
  std::vector<std::int32_t> t;
  double area = 0;
  void tri(Vec3 a, Vec3 b, Vec3 c) {
    const auto base = static_cast<std::int32_t>(v.size() / 3);
    for (Vec3 p : {a, b, c}) v.insert(v.end(), {p.x, p.y, p.z});
    t.insert(t.end(), {base, base + 1, base + 2});
    area += 0.5 * length(cross(b - a, c - a));
  }
  void quad(Vec3 c, Vec3 u, Vec3 w) {  // centre, half-edge vectors
    tri(c - u - w, c + u - w, c + u + w);
    tri(c - u - w, c + u + w, c - u + w);
  }
  PointsView view() const { return {v.data(), v.size() / 3}; }
  DensityGrid grid(int res) const {
    DensityGridOptions o;
    o.resolution = res;
    return DensityGrid(view(), t.data(), t.size() / 3, o);
  }
};

// The paper's idealised canopy: small randomly oriented equilateral triangles uniformly spread
// in the unit ball, total area A = 2·σ·V so the medium has σR = tau.
Mesh random_ball(int count, float tau, std::uint64_t seed) {
  const double vol = 4.0 / 3.0 * kPi;
  const double a_each = 2.0 * tau * vol / count;
  const float circ = std::sqrt(static_cast<float>(a_each) / (3 * std::sqrt(3.0f) / 4));
  Rng rng(seed);
  Mesh m;
  for (int i = 0; i < count; ++i) {
    const Vec3 c = rng.in_ball(), n = rng.unit();
    const Vec3 t1 = normalize(cross(n, std::abs(n.x) < 0.9f ? Vec3{1, 0, 0} : Vec3{0, 1, 0}));
    const Vec3 t2 = cross(n, t1);
    const float p0 = 2 * kPi * rng.uniform();
    Vec3 p[3];
    for (int k = 0; k < 3; ++k) {
      const float a = p0 + 2 * kPi * k / 3;
      p[k] = c + (t1 * std::cos(a) + t2 * std::sin(a)) * circ;
    }
    m.tri(p[0], p[1], p[2]);
  }
  return m;
}

std::vector<float> run_ao(const DensityGrid& g, const std::vector<float>& pos,
                          const std::vector<float>& nrm, DensityAOOptions o = {}) {
  std::vector<float> out(pos.size() / 3);
  g.ao({pos.data(), pos.size() / 3}, {nrm.data(), nrm.size() / 3}, o, out.data());
  return out;
}

}  // namespace

class DensityBall : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { ball_ = new Mesh(random_ball(60000, 2.0f, 7)); }
  static void TearDownTestSuite() { delete ball_; }
  static Mesh* ball_;
};
Mesh* DensityBall::ball_ = nullptr;

TEST_F(DensityBall, SigmaFromLeafAreaRecoversTheGeneratedDensity) {
  // σ = A/(2V) = τ/R = 2 inside; the mean over interior voxels within 3%.
  const DensityGrid g = ball_->grid(32);
  EXPECT_NEAR(g.total_area(), ball_->area, 1e-6 * ball_->area);
  double sum = 0;
  int n = 0;
  for (int k = 0; k < g.nz(); ++k)
    for (int j = 0; j < g.ny(); ++j)
      for (int i = 0; i < g.nx(); ++i) {
        const Vec3 c = g.origin() + Vec3{i + 0.5f, j + 0.5f, k + 0.5f} * g.voxel_size();
        if (length(c) < 0.8f) sum += g.sigma(i, j, k), ++n;
      }
  EXPECT_NEAR(sum / n, 2.0, 0.06);
  // Optical mass is conserved on every mip level.
  for (int l = 0; l < g.levels(); ++l) {
    double s = 0;
    for (float v : g.sigma_level(l)) s += v;
    const float vox = g.voxel_size() * float(1 << l);
    EXPECT_NEAR(s * vox * vox * vox * 2, ball_->area, 1e-3 * ball_->area) << "level " << l;
  }
}

TEST_F(DensityBall, AOMatchesTheUniformMediumExpectation) {
  // Receivers in the interior (r ≤ 0.6, not on leaves) against the tabulated expectation for
  // the same σR = 2: |ΔAO| < 0.03 each, mean |ΔAO| < 0.01 (voxel noise of ~3.5 leaves per
  // voxel, the blurred ball boundary, and the cone steps all included).
  const DensityGrid g = ball_->grid(32);
  Rng rng(3);
  std::vector<float> pos, nrm;
  for (int i = 0; i < 200; ++i) {
    const Vec3 p = rng.in_ball() * 0.6f, n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  DensityAOOptions o;
  o.directions = 128;
  const std::vector<float> ao = run_ao(g, pos, nrm, o);
  const MediumTable& table = MediumTable::get();
  double mean = 0, worst = 0, bias = 0;
  for (int i = 0; i < 200; ++i) {
    const Vec3 p{pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]};
    const Vec3 n{nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2]};
    const float r = length(p);
    const float ref = table.ao(r, r > 0 ? dot(p, n) / r : 0.0f, 2.0f);
    const double d = ao[i] - ref;
    mean += std::abs(d) / 200;
    bias += d / 200;
    worst = std::max(worst, std::abs(d));
  }
  std::printf("[density grid] vs medium table (tau=2, 128 dirs): mean |d| %.4f, bias %+.4f, "
              "worst %.4f\n", mean, bias, worst);
  EXPECT_LT(worst, 0.03);
  EXPECT_LT(mean, 0.01);
}

TEST_F(DensityBall, DeterministicAndThreadCountIndependent) {
  const DensityGrid g = ball_->grid(24);
  Rng rng(5);
  std::vector<float> pos, nrm;
  for (int i = 0; i < 3000; ++i) {
    const Vec3 p = rng.in_ball() * 1.3f, n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  const int prev = set_max_threads(1);
  const std::vector<float> a = run_ao(g, pos, nrm);
  set_max_threads(0);
  const std::vector<float> b = run_ao(g, pos, nrm);
  const std::vector<float> c = run_ao(g, pos, nrm);
  set_max_threads(prev);
  EXPECT_EQ(a, b);
  EXPECT_EQ(b, c);
  DensityAOOptions o;
  o.seed = 1;
  EXPECT_NE(run_ao(g, pos, nrm, o), a);  // the seed changes the noise
}

TEST_F(DensityBall, CostDoesNotDependOnLeafCount) {
  // Same grid resolution, 60k vs 600 leaves of the same total area: AO time per receiver of the
  // same order (the march sees voxels, not leaves). Reported, loosely checked.
  const Mesh few = random_ball(600, 2.0f, 9);
  const DensityGrid g1 = ball_->grid(32), g2 = few.grid(32);
  Rng rng(11);
  std::vector<float> pos, nrm;
  for (int i = 0; i < 10000; ++i) {
    const Vec3 p = rng.in_ball(), n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  auto time = [&](const DensityGrid& g) {
    const auto t0 = std::chrono::steady_clock::now();
    run_ao(g, pos, nrm);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  const double a = time(g1), b = time(g2);
  std::printf("[density grid] 10k receivers x 32 dirs: 60k leaves %.3f s, 600 leaves %.3f s\n",
              a, b);
  EXPECT_LT(a, 5 * b + 0.05);
}

TEST_F(DensityBall, NearExactFarStatistical) {
  // Against Embree at 512 rays: the grid alone, and Embree to 4 voxels + the grid beyond.
  // Both within 0.03 on average on the idealised ball (a known-answer scene for both), and
  // the split is consistent at its limits: start beyond the ball → the grid gives 1; near
  // beyond the ball → exactly the traced answer.
  const DensityGrid g = ball_->grid(32);
  const RayTracer rt(ball_->view(), ball_->t.data(), ball_->t.size() / 3);
  Rng rng(13);
  std::vector<float> pos, nrm;
  for (int i = 0; i < 150; ++i) {
    const Vec3 p = rng.in_ball() * 0.7f, n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  const PointsView p{pos.data(), 150}, n{nrm.data(), 150};
  RayTraceOptions ref_opt;
  ref_opt.samples = 512;
  std::vector<float> ref(150), grid_only(150), split(150), far_only(150), all_traced(150);
  rt.ao(p, n, ref_opt, ref.data());
  DensityAOOptions o;
  o.directions = 64;
  g.ao(p, n, o, grid_only.data());
  RayTraceOptions near_opt;
  near_opt.samples = 64;
  ao_near_far(rt, g, p, n, 4 * g.voxel_size(), near_opt, o, split.data());
  double eg = 0, es = 0;
  for (int i = 0; i < 150; ++i) eg += std::abs(grid_only[i] - ref[i]) / 150;
  for (int i = 0; i < 150; ++i) es += std::abs(split[i] - ref[i]) / 150;
  std::printf("[density grid] vs Embree 512 rays: grid mean |d| %.4f, near/far %.4f\n", eg, es);
  EXPECT_LT(eg, 0.03);
  EXPECT_LT(es, 0.03);
  o.start = 5.0f;
  g.ao(p, n, o, far_only.data());
  for (float v : far_only) EXPECT_EQ(v, 1.0f);
  rt.ao(p, n, near_opt, all_traced.data());
  ao_near_far(rt, g, p, n, 5.0f, near_opt, o, split.data());
  EXPECT_EQ(split, all_traced);
}

TEST(DensityGrid, EmptyMeshIsOpenSky) {
  std::vector<float> v;
  std::vector<std::int32_t> t;
  const DensityGrid g({v.data(), 0}, t.data(), 0);
  EXPECT_TRUE(g.empty());
  EXPECT_EQ(g.total_area(), 0.0);
  const std::vector<float> pos = {0, 0, 0, 1, 2, 3}, nrm = {0, 0, 1, 0, 0, 0};
  for (float a : run_ao(g, pos, nrm)) EXPECT_EQ(a, 1.0f);
  // degenerate (zero-area) triangles only: also empty
  Mesh m;
  m.tri({0, 0, 0}, {1, 1, 1}, {2, 2, 2});
  EXPECT_TRUE(m.grid(16).empty());
}

TEST(DensityGrid, DenseSlabBlocks) {
  // 40 stacked 10×10 layers in z ∈ [0, 1] (σ = 40·100/(2·100·1) = 20 per unit): a receiver
  // under it facing up is nearly black; above it facing up, open; facing down from above, dark.
  Mesh m;
  for (int i = 0; i < 40; ++i) m.quad({0, 0, (i + 0.5f) / 40}, {5, 0, 0}, {0, 5, 0});
  const DensityGrid g = m.grid(40);
  const std::vector<float> pos = {0, 0, -0.2f, 0, 0, 1.2f, 0, 0, 1.2f};
  const std::vector<float> nrm = {0, 0, 1, 0, 0, 1, 0, 0, -1};
  const std::vector<float> ao = run_ao(g, pos, nrm);
  EXPECT_LT(ao[0], 0.03f);
  EXPECT_EQ(ao[1], 1.0f);
  EXPECT_LT(ao[2], 0.03f);
  // the AO distance cuts the slab off
  DensityAOOptions o;
  o.distance = 0.15f;
  EXPECT_EQ(run_ao(g, pos, nrm, o)[0], 1.0f);
}

TEST(DensityGrid, ExactIntegrationThroughAUniformBlock) {
  // A filled box: the near-field DDA and the coarse steps both give σ·length along an axis ray.
  Mesh m;
  for (int i = 0; i < 64; ++i) m.quad({0, 0, (i + 0.5f) / 16 - 2}, {2, 0, 0}, {0, 2, 0});
  const DensityGrid g = m.grid(32);  // 4×4×4 box, 64 layers of area 16: σ = 64·16/(2·64) = 8
  const float d = g.optical_depth({0.01f, 0.02f, -1.0f}, {0, 0, 1}, 1.5f, 0.0f, 0.25f);
  EXPECT_NEAR(d, 8 * 1.5f, 0.02f * 12);
  const float slanted = g.optical_depth({0.01f, 0.02f, -1.0f}, normalize({0.3f, 0.2f, 1}), 1.2f,
                                        1.0f, 0.25f);
  EXPECT_NEAR(slanted, 8 * 1.2f, 0.03f * 9.6f);
}

TEST(DensityGrid, ReceiverOnALeafDoesNotSeeItsOwnLeaf) {
  // One 0.1×0.1 leaf (voxel h = 0.1: a far speck sets the box) — the receiver at its centre,
  // facing along its normal. Own-leaf self-occlusion would darken it to ~0.7; the diluted
  // first voxel keeps it open.
  Mesh m;
  m.quad({0.02f, 0.03f, 0.01f}, {0.05f, 0, 0}, {0, 0.05f, 0});
  m.tri({4.0f, 4.0f, 4.0f}, {4.01f, 4.0f, 4.0f}, {4.0f, 4.01f, 4.0f});
  const DensityGrid g = m.grid(40);
  const std::vector<float> pos = {0.02f, 0.03f, 0.01f}, nrm = {0, 0, 1};
  DensityAOOptions raw;
  raw.self_skip = 0;
  const float with = run_ao(g, pos, nrm)[0], without = run_ao(g, pos, nrm, raw)[0];
  std::printf("[density grid] own leaf: AO %.3f with self_skip=1, %.3f with 0\n", with, without);
  EXPECT_GT(with, 0.95f);
  EXPECT_LT(without, with - 0.05f);
}

TEST(DensityGrid, BadInputThrows) {
  Mesh m;
  m.quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
  DensityGridOptions o;
  o.resolution = 0;
  EXPECT_THROW(DensityGrid(m.view(), m.t.data(), 2, o), std::invalid_argument);
  o.resolution = 1025;
  EXPECT_THROW(DensityGrid(m.view(), m.t.data(), 2, o), std::invalid_argument);
  o.resolution = 16;
  std::vector<float> v = m.v;
  v[4] = NAN;
  EXPECT_THROW(DensityGrid({v.data(), v.size() / 3}, m.t.data(), 2, o), std::invalid_argument);
  std::vector<std::int32_t> t = m.t;
  t[5] = 99;
  EXPECT_THROW(DensityGrid(m.view(), t.data(), 2, o), std::invalid_argument);
  const DensityGrid g = m.grid(16);
  std::vector<float> pos = {0, 0, NAN}, nrm = {0, 0, 1};
  EXPECT_THROW(run_ao(g, pos, nrm), std::invalid_argument);
  pos[2] = 0;
  DensityAOOptions bad;
  bad.directions = 0;
  EXPECT_THROW(run_ao(g, pos, nrm, bad), std::invalid_argument);
  bad = {};
  bad.distance = -1;
  EXPECT_THROW(run_ao(g, pos, nrm, bad), std::invalid_argument);
  bad = {};
  bad.sigma_scale = NAN;
  EXPECT_THROW(run_ao(g, pos, nrm, bad), std::invalid_argument);
}

// === Occlusion features (occlusion_features.h): the sweeps against the grid's own marcher.

namespace {
std::vector<float> features(const OcclusionFeatures& f, const std::vector<float>& pos,
                            const std::vector<float>& nrm, TreeFrame fr = {}) {
  std::vector<float> out(pos.size() / 3 * OcclusionFeatures::kCount);
  f.compute({pos.data(), pos.size() / 3}, {nrm.data(), nrm.size() / 3}, fr, out.data());
  return out;
}
}  // namespace

TEST_F(DensityBall, OcclusionFeaturesGridAOAtTheCentreIsExpMinusTau) {
  // Uniform medium with σR = 2: every direction from the centre has optical depth 2.
  const DensityGrid g = ball_->grid(48);
  const OcclusionFeatures f(g);
  const auto o = features(f, {0, 0, 0}, {0, 0, 1});
  EXPECT_NEAR(o[1], std::exp(-2.0f), 0.03f);
  EXPECT_NEAR(o[0], std::exp(-1.0f), 0.04f);  // σ scale ½
  EXPECT_NEAR(o[2], std::exp(-4.0f), 0.02f);  // σ scale 2
  EXPECT_NEAR(o[3], std::exp(-2.0f), 0.03f);  // sky view: the same depth upward
}

TEST_F(DensityBall, OcclusionFeaturesAgreeWithTheGridMarcherInsideAndOutside) {
  // Two implementations of the same line integrals (sweeps here, DDA + mips there): receivers
  // inside the ball, on its rim and outside it (the outside path enters the grid per direction).
  const DensityGrid g = ball_->grid(48);
  const OcclusionFeatures f(g, {64});
  std::vector<float> pos, nrm;
  Rng rng(3);
  for (int i = 0; i < 40; ++i) {
    const float r = 1.6f * rng.uniform();
    const Vec3 p = rng.unit() * r, n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  DensityAOOptions o;
  o.directions = 2048;
  o.self_skip = 0;
  const auto ref = run_ao(g, pos, nrm, o);
  const auto got = features(f, pos, nrm);
  double err = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    err += std::fabs(got[i * OcclusionFeatures::kCount + 1] - ref[i]);
    EXPECT_NEAR(got[i * OcclusionFeatures::kCount + 1], ref[i], 0.08f) << "receiver " << i;
  }
  EXPECT_LT(err / ref.size(), 0.03);
}

TEST(OcclusionFeatures, EmptyGridIsOpenSkyAndShapeFeaturesFollowTheFrame) {
  Mesh m;
  const DensityGrid g = m.grid(8);
  const OcclusionFeatures f(g);
  TreeFrame fr;
  fr.center = {1, 0, 0};
  fr.radius = 2;
  fr.z_min = 0;
  fr.z_max = 4;
  const auto o = features(f, {3, 0, 1}, {1, 0, 0}, fr);
  for (int k : {0, 1, 2, 3}) EXPECT_FLOAT_EQ(o[k], 1.0f);
  EXPECT_FLOAT_EQ(o[5], 0.0f);   // no leaves here
  EXPECT_FLOAT_EQ(o[6], 0.0f);   // normal horizontal
  EXPECT_FLOAT_EQ(o[7], 1.0f);   // facing away from the axis
  EXPECT_FLOAT_EQ(o[8], 0.25f);  // a quarter up the tree
  EXPECT_FLOAT_EQ(o[9], 1.0f);   // at the tree's radius
}

TEST_F(DensityBall, OcclusionFeaturesDoNotDependOnTheThreadCount) {
  const DensityGrid g = ball_->grid(32);
  std::vector<float> pos, nrm;
  Rng rng(5);
  for (int i = 0; i < 3000; ++i) {
    const Vec3 p = rng.in_ball() * 1.3f, n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  const int prev = set_max_threads(1);
  const auto one = features(OcclusionFeatures(g), pos, nrm);
  set_max_threads(0);
  const auto all = features(OcclusionFeatures(g), pos, nrm);
  set_max_threads(prev);
  EXPECT_EQ(one, all);
}

TEST_F(DensityBall, OcclusionFeaturesAreTheSameBitsWithAndWithoutTheBucketTiles) {
  // compute() copies a bucket's τ corners into a tile when enough receivers share the bucket
  // (occlusion_features.cpp, features_block); a receiver alone reads the field directly. Each
  // receiver computed alone, then all together in their buckets: the same bits, whatever the
  // directions (24 fill three 8-lane groups, 13 leave a padded one).
  const DensityGrid g = ball_->grid(24);
  std::vector<float> pos, nrm;
  Rng rng(11);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 p = rng.in_ball() * 1.2f, n = rng.unit();  // inside the box and a few outside
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  for (int k : {24, 13}) {
    const OcclusionFeatures f(g, {k});
    const auto together = features(f, pos, nrm);
    for (std::size_t i = 0; i < pos.size() / 3; i += 37) {
      const auto alone = features(f, {pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]},
                                  {nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2]});
      for (int c = 0; c < OcclusionFeatures::kCount; ++c)
        ASSERT_EQ(alone[c], together[i * OcclusionFeatures::kCount + c])
            << "receiver " << i << " feature " << c << " with " << k << " directions";
    }
  }
}

TEST_F(DensityBall, OcclusionFeaturesAreTheSameBitsOnTheAvx2Kernel) {
  // The AVX2 copy of the per-receiver work is built without FMA, so it must give the
  // baseline's bits (occlusion_features.h, occlusion_features_kernel_avx2).
  const bool was = occlusion_features_kernel_avx2();
  try {
    set_occlusion_features_kernel_avx2(true);
  } catch (const std::invalid_argument&) {
    GTEST_SKIP() << "no AVX2 on this CPU";
  }
  const DensityGrid g = ball_->grid(32);
  std::vector<float> pos, nrm;
  Rng rng(12);
  for (int i = 0; i < 3000; ++i) {
    const Vec3 p = rng.in_ball() * 1.4f, n = rng.unit();
    pos.insert(pos.end(), {p.x, p.y, p.z});
    nrm.insert(nrm.end(), {n.x, n.y, n.z});
  }
  for (int k : {24, 13}) {
    const OcclusionFeatures f(g, {k});
    set_occlusion_features_kernel_avx2(true);
    const auto avx = features(f, pos, nrm);
    set_occlusion_features_kernel_avx2(false);
    const auto base = features(f, pos, nrm);
    EXPECT_EQ(avx, base) << k << " directions";
  }
  set_occlusion_features_kernel_avx2(was);
}

TEST(OcclusionFeatures, BadInputThrows) {
  Mesh m;
  m.quad({0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0});
  const DensityGrid g = m.grid(8);
  EXPECT_THROW(OcclusionFeatures(g, {5}), std::invalid_argument);
  EXPECT_THROW(OcclusionFeatures(g, {257}), std::invalid_argument);
  const OcclusionFeatures f(g);
  TreeFrame bad;
  bad.radius = 0;
  std::vector<float> out(OcclusionFeatures::kCount);
  const std::vector<float> p = {0, 0, 0}, n = {0, 0, 1}, nan = {NAN, 0, 0};
  EXPECT_THROW(f.compute({p.data(), 1}, {n.data(), 1}, bad, out.data()), std::invalid_argument);
  EXPECT_THROW(f.compute({nan.data(), 1}, {n.data(), 1}, {}, out.data()), std::invalid_argument);
}

TEST(OcclusionFeatures, PredictModelGivesTheSameBitsRowByRowInBlocksAndOnAvx2) {
  // predict_model evaluates 8 rows at a time (the same terms in the same order as one row's
  // expansion) and one by one for the rest of a block: a row alone, the rows together and the
  // AVX2 copy give the same bits, with the piece columns (F = 17 over F_native = 13), the
  // bounds held and without them.
  const int F = 17, FN = OcclusionFeatures::kCount, N = 203;
  const int P = model_size(F, FN);
  Rng rng(21);
  std::vector<float> x(N * F), mean(F), scale(F), lo(F), hi(F), w(P);
  for (float& v : x) v = 4 * rng.uniform() - 2;
  for (int j = 0; j < F; ++j) {
    mean[j] = rng.uniform() - 0.5f, scale[j] = 0.5f + rng.uniform();
    lo[j] = -1.5f, hi[j] = 1.5f;
  }
  for (float& v : w) v = 0.2f * (rng.uniform() - 0.5f);
  w[0] = 0.5f;
  const bool was = occlusion_features_kernel_avx2();
  bool has_avx2 = true;
  try {
    set_occlusion_features_kernel_avx2(true);
  } catch (const std::invalid_argument&) {
    has_avx2 = false;
  }
  for (const bool bounded : {false, true}) {
    const float* l = bounded ? lo.data() : nullptr;
    const float* h = bounded ? hi.data() : nullptr;
    std::vector<float> alone(N), together(N), base(N);
    for (int i = 0; i < N; ++i)
      predict_model(&x[i * F], 1, F, FN, mean.data(), scale.data(), w.data(), l, h, &alone[i]);
    set_occlusion_features_kernel_avx2(false);
    predict_model(x.data(), N, F, FN, mean.data(), scale.data(), w.data(), l, h, base.data());
    EXPECT_EQ(alone, base) << "bounded " << bounded;
    if (has_avx2) {
      set_occlusion_features_kernel_avx2(true);
      predict_model(x.data(), N, F, FN, mean.data(), scale.data(), w.data(), l, h,
                    together.data());
      EXPECT_EQ(together, base) << "bounded " << bounded;
    }
  }
  if (has_avx2) set_occlusion_features_kernel_avx2(was);
}

TEST(OcclusionFeatures, LinearModelExpandsAndPredictsAsDocumented) {
  // F = 3 features: φ = [1, z0, z1, z2, z0², z1², z2², z1·z0, z1·z2] (products with feature 1).
  const int F = 3;
  ASSERT_EQ(expanded_size(F), 9);
  const float x[F] = {3, 5, 7}, mean[F] = {1, 1, 1}, scale[F] = {2, 4, 3};
  float phi[9];
  expand_features(x, 1, F, mean, scale, phi);
  const float z0 = 1, z1 = 1, z2 = 2;
  const float want[9] = {1, z0, z1, z2, z0 * z0, z1 * z1, z2 * z2, z1 * z0, z1 * z2};
  for (int p = 0; p < 9; ++p) EXPECT_FLOAT_EQ(phi[p], want[p]) << p;
  float w[9] = {0.1f, 0.2f, 0, 0, 0, 0, 0, 0, 0};
  float ao = -1;
  predict_features(x, 1, F, mean, scale, w, &ao);
  EXPECT_FLOAT_EQ(ao, 0.3f);
  w[0] = 5;  // clamped to [0, 1]
  predict_features(x, 1, F, mean, scale, w, &ao);
  EXPECT_FLOAT_EQ(ao, 1.0f);
  const float zero_scale[F] = {1, 0, 1};
  EXPECT_THROW(predict_features(x, 1, F, mean, zero_scale, w, &ao), std::invalid_argument);
}
