// The scene plan (scene_plan.h): its composition equals the kernels it is made of, grouped
// occluder fields equal the plain ones, the grass covers (grass_cover.h) equal the disc counted
// offset by offset, the forest (forest.h) is its fields' product, bad input throws, empty input
// is fine.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

#include "canopy_ao/canopy_model.h"
#include "canopy_ao/forest.h"
#include "canopy_ao/grass.h"
#include "canopy_ao/grass_cover.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/scene_plan.h"
#include "test_points.h"

using namespace canopy_ao;
using canopy_ao::test::view;

namespace {

Ellipsoid ball(float x, float y, float z, float r) {
  return Ellipsoid::from_sphere(Sphere{{x, y, z}, r});
}

// A crown of two shells around (cx, 0, 3) and a trunk below it.
TreeProxies tree_at(float cx) {
  TreeProxies t;
  t.has_crown = true;
  t.sphere = Sphere{{cx, 0, 3}, 1.5f};
  t.ellipsoid = Ellipsoid::from_sphere(t.sphere);
  t.ellipsoid.radii = {1.5f, 1.2f, 1.0f};
  t.shells = {ball(cx - 0.5f, 0, 3, 1.0f), ball(cx + 0.5f, 0, 3.2f, 0.9f)};
  t.trunks = {ball(cx, 0, 1, 0.3f)};
  t.trunks[0].radii = {0.2f, 0.2f, 1.0f};
  return t;
}

// Whether x lies in one of the tree's crown shells (the receivers a crown claims).
bool in_crown(const TreeProxies& t, Vec3 x) {
  for (const Ellipsoid& s : t.shells) {
    if (s.contains(x)) return true;
  }
  return false;
}

// Points spread over the two crowns (which interlock), the ground and the air, with
// random unit normals.
void scatter(std::vector<float>& p, std::vector<float>& n, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int i = 0; i < count; ++i) {
    test::add(p, 2.5 * u(rng), 1.5 * u(rng), 2.5 + 2.5 * u(rng));
    float a = u(rng), b = u(rng), c = u(rng);
    const float l = std::sqrt(a * a + b * b + c * c) + 1e-3f;
    test::add(n, a / l, b / l, c / l);
  }
}

}  // namespace

TEST(OccluderFieldGroups, SameMaterialEveryGroupEqualsThePlainField) {
  const std::vector<Ellipsoid> shells = {ball(0, 0, 3, 1), ball(2, 0, 3, 1), ball(5, 1, 2, 2)};
  OccluderOptions o;
  o.tau = 1.3f;
  const OccluderField plain(shells, o), grouped(shells, o, {0, 1, 1});
  const OccluderMaterial m = OccluderMaterial::of(o);
  const OccluderMaterial* by_group[2] = {&m, &m};
  const OccluderField without_group1({shells[0]}, o);
  std::vector<float> p, n;
  scatter(p, n, 400, 3);
  for (std::size_t i = 0; i < p.size() / 3; ++i) {
    const Vec3 x = view(p)[i], nv = view(n)[i];
    EXPECT_NEAR(grouped.visibility(x, nv, by_group, -1), plain.visibility(x, nv), 1e-6);
    EXPECT_NEAR(grouped.visibility(x, nv, by_group, 1), without_group1.visibility(x, nv), 1e-6);
  }
}

TEST(OccluderFieldGroups, RefusesGroupsThatDoNotMatchTheShells) {
  OccluderOptions o;
  EXPECT_THROW(OccluderField({ball(0, 0, 0, 1)}, o, {0, 1}), std::invalid_argument);
  EXPECT_THROW(OccluderField({ball(0, 0, 0, 1)}, o, {-1}), std::invalid_argument);
}

TEST(ScenePlan, CompositionIsInShellTimesOtherCrownsTimesOtherTrunks) {
  const std::vector<TreeProxies> trees = {tree_at(-0.8f), tree_at(0.8f)};  // interlocking
  ScenePlanOptions po;
  po.distance = 4.0f;
  const ScenePlan plan(trees, po);
  const std::vector<float> tau = {0.7f, 2.1f};
  std::vector<float> p, n;
  scatter(p, n, 3000, 7);
  const std::size_t count = p.size() / 3;
  PlanReceivers canopy0;
  canopy0.role = ReceiverRole::Canopy;
  canopy0.tree = 0;
  std::vector<float> got(count);
  plan.evaluate(view(p), view(n), canopy0, PlanMethod::Shells, tau, got.data());

  OccluderOptions oo;
  oo.distance = po.distance;
  std::vector<OccluderField> crowns, trunks;
  for (std::size_t t = 0; t < 2; ++t) {
    oo.tau = tau[t];
    crowns.emplace_back(trees[t].shells, oo);
  }
  OccluderOptions solid = oo;
  solid.solid = true;
  const OccluderField trunk1(trees[1].trunks, solid);
  int inside[3] = {0, 0, 0};
  for (std::size_t i = 0; i < count; ++i) {
    const Vec3 x = view(p)[i], nv = view(n)[i];
    int claim = -1;
    for (int t = 0; t < 2 && claim < 0; ++t) {
      for (const Ellipsoid& s : trees[t].shells) claim = s.contains(x) ? t : claim;
    }
    ++inside[claim + 1];
    float want = 1.0f;
    if (claim >= 0) {
      const float pt[3] = {x.x, x.y, x.z}, nt[3] = {nv.x, nv.y, nv.z};
      ao_canopy_shells({pt, 1}, {nt, 1}, trees[claim].shells, CanopyOptions{tau[claim], 0.1f},
                       ShellCombine::Product, &want);
    }
    for (int t = 0; t < 2; ++t) {
      if (t != claim) want *= crowns[t].visibility(x, nv);
    }
    want *= trunk1.visibility(x, nv);  // not tree 0's own trunk
    ASSERT_NEAR(got[i], std::clamp(want, 0.0f, 1.0f), 2e-6) << "point " << i;
  }
  // The scene exercises every case: outside every crown, inside the first, inside the second.
  EXPECT_GT(inside[0], 100);
  EXPECT_GT(inside[1], 100);
  EXPECT_GT(inside[2], 100);
}

// One tree's own leaves, all inside its crown: the in-shell kernel alone (its own trunk is
// skipped); a second tree's bare trunk or a receiver outside the crown brings the occluders
// back (the plan's shortcut for the one-crown case must not drop them).
TEST(ScenePlan, OneCrownHoldingEveryReceiverIsTheInShellModelAlone) {
  const TreeProxies tree = tree_at(0.0f);
  TreeProxies bare = tree_at(2.5f);  // a trunk, no crown
  bare.has_crown = false;
  bare.shells.clear();
  std::vector<float> p, n;
  for (int i = 0; i < 200; ++i) {
    const float a = 0.1f * i;
    test::add(p, 0.6f * std::cos(a), 0.4f * std::sin(a), 3.0f + 0.3f * std::sin(3 * a));
    test::add(n, std::cos(a), std::sin(a), 0.2f);
  }
  const std::size_t count = p.size() / 3;
  for (std::size_t i = 0; i < count; ++i) ASSERT_TRUE(in_crown(tree, view(p)[i])) << i;
  PlanReceivers own;
  own.role = ReceiverRole::Canopy;
  own.tree = 0;
  std::vector<float> want(count), alone(count), beside(count);
  ao_canopy_sphere(view(p), view(n), tree.sphere, CanopyOptions{1.5f, 0.1f}, want.data());
  ScenePlan({tree}, ScenePlanOptions{})
      .evaluate(view(p), view(n), own, PlanMethod::Sphere, {1.5f}, alone.data());
  ScenePlan({tree, bare}, ScenePlanOptions{})
      .evaluate(view(p), view(n), own, PlanMethod::Sphere, {1.5f, 1.0f}, beside.data());
  int darker = 0;
  for (std::size_t i = 0; i < count; ++i) {
    ASSERT_EQ(alone[i], want[i]) << "point " << i;
    ASSERT_LE(beside[i], want[i] + 1e-7f) << "point " << i;
    darker += beside[i] < want[i] - 1e-4f;
  }
  EXPECT_GT(darker, 10);  // the other tree's trunk occludes some of them
  // A receiver outside the crown sees it as an occluder.
  const float out_p[3] = {0.0f, 0.0f, 6.0f}, out_n[3] = {0.0f, 0.0f, -1.0f};
  float v = 1.0f;
  ScenePlan({tree}, ScenePlanOptions{})
      .evaluate({out_p, 1}, {out_n, 1}, own, PlanMethod::Sphere, {1.5f}, &v);
  EXPECT_LT(v, 0.9f);
}

TEST(ScenePlan, GroundSeesEveryTrunkAndGrassGetsTheGrassLaw) {
  const ScenePlan plan({tree_at(-3.0f), tree_at(3.0f)}, ScenePlanOptions{});
  std::vector<float> p, n;
  for (int i = 0; i < 50; ++i) {
    test::add(p, -6 + 0.24 * i, 0.3, 0.1);
    test::add(n, 0, 0, 1);
  }
  const std::size_t count = p.size() / 3;
  const std::vector<float> tau = {1.0f, 1.0f};
  PlanReceivers ground;  // tree −1: no trunk is its own
  PlanReceivers trunk0;
  trunk0.role = ReceiverRole::Trunk;
  trunk0.tree = 0;
  PlanReceivers grass;
  grass.role = ReceiverRole::Grass;
  grass.tree = 0;  // grass never owns a trunk
  grass.grass.ground_height = 0.0f;
  grass.grass.blade_height = 0.3f;
  std::vector<float> g(count), t(count), b(count), law(count);
  plan.evaluate(view(p), view(n), ground, PlanMethod::Ellipsoid, tau, g.data());
  plan.evaluate(view(p), view(n), trunk0, PlanMethod::Ellipsoid, tau, t.data());
  plan.evaluate(view(p), view(n), grass, PlanMethod::Ellipsoid, tau, b.data());
  ao_grass(view(p), view(n), grass.grass, law.data());
  int darker = 0;
  for (std::size_t i = 0; i < count; ++i) {
    EXPECT_LE(g[i], t[i] + 1e-7f);  // the ground also sees tree 0's own trunk
    darker += g[i] < t[i] - 1e-4f;
    EXPECT_NEAR(b[i], g[i] * law[i], 1e-6);
  }
  EXPECT_GT(darker, 0);
}

TEST(ScenePlan, NoTreesAndNoReceiversAreFine) {
  const ScenePlan empty({}, ScenePlanOptions{});
  std::vector<float> p = {0, 0, 0, 1, 2, 3}, n = {0, 0, 1, 0, 0, 0};
  std::vector<float> out(2, -1.0f);
  empty.evaluate(view(p), view(n), PlanReceivers{}, PlanMethod::Medium, {}, out.data());
  EXPECT_EQ(out[0], 1.0f);
  EXPECT_EQ(out[1], 1.0f);
  const ScenePlan plan({tree_at(0)}, ScenePlanOptions{});
  plan.evaluate(PointsView{nullptr, 0}, PointsView{nullptr, 0}, PlanReceivers{},
                PlanMethod::Sphere, {1.0f}, nullptr);
}

TEST(ScenePlan, BadInputThrows) {
  TreeProxies no_shells = tree_at(0);
  no_shells.shells.clear();
  EXPECT_THROW(ScenePlan({no_shells}, ScenePlanOptions{}), std::invalid_argument);
  TreeProxies flat = tree_at(0);
  flat.ellipsoid.radii.y = 0;
  EXPECT_THROW(ScenePlan({flat}, ScenePlanOptions{}), std::invalid_argument);
  TreeProxies bad_trunk = tree_at(0);
  bad_trunk.trunks[0].radii.x = -1;
  EXPECT_THROW(ScenePlan({bad_trunk}, ScenePlanOptions{}), std::invalid_argument);
  ScenePlanOptions no_distance;
  no_distance.distance = 0;
  EXPECT_THROW(ScenePlan({tree_at(0)}, no_distance), std::invalid_argument);

  const ScenePlan plan({tree_at(0), tree_at(4)}, ScenePlanOptions{});
  std::vector<float> p = {0, 0, 3}, n = {0, 0, 1}, out(1);
  PlanReceivers r;
  EXPECT_THROW(plan.evaluate(view(p), view(n), r, PlanMethod::Shells, {1.0f}, out.data()),
               std::invalid_argument);  // one τ for two trees
  EXPECT_THROW(plan.evaluate(view(p), view(n), r, PlanMethod::Shells, {1.0f, NAN}, out.data()),
               std::invalid_argument);
  r.tree = 2;
  EXPECT_THROW(plan.evaluate(view(p), view(n), r, PlanMethod::Shells, {1.0f, 1.0f}, out.data()),
               std::invalid_argument);
  const std::int32_t trees[1] = {-2};
  r.tree = 0;
  r.trees = trees;
  EXPECT_THROW(plan.evaluate(view(p), view(n), r, PlanMethod::Shells, {1.0f, 1.0f}, out.data()),
               std::invalid_argument);
  PlanReceivers grass;
  grass.role = ReceiverRole::Grass;
  grass.grass.blade_height = 0;
  EXPECT_THROW(
      plan.evaluate(view(p), view(n), grass, PlanMethod::Shells, {1.0f, 1.0f}, out.data()),
      std::invalid_argument);
}

TEST(ScenePlan, SmallCrownsFarFromTheOriginClaimTheirPoints) {
  // Coordinates ~1e6 with radii ~1e-2 (both in the accepted range): the cheap bounding test
  // that skips far trees must not lose a point its crown's shells hold.
  TreeProxies t;
  t.has_crown = true;
  t.sphere = Sphere{{1e6f, -1e6f, 5e5f}, 0.02f};
  t.ellipsoid = Ellipsoid::from_sphere(t.sphere);
  t.shells = {ball(1e6f - 0.01f, -1e6f, 5e5f, 0.012f), ball(1e6f + 0.01f, -1e6f, 5e5f, 0.011f)};
  const ScenePlan plan({t}, ScenePlanOptions{});
  std::vector<float> p, n;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  for (const Ellipsoid& s : t.shells) {
    for (int i = 0; i < 200; ++i) {
      const Vec3 d = normalize(Vec3{u(rng), u(rng), u(rng)}) * (s.radii.x * 0.999f);
      test::add(p, s.center.x + d.x, s.center.y + d.y, s.center.z + d.z);
      test::add(n, 0, 0, 1);
    }
  }
  const std::size_t count = p.size() / 3;
  std::vector<float> got(count), want(count);
  PlanReceivers canopy;
  canopy.role = ReceiverRole::Canopy;
  canopy.tree = 0;
  plan.evaluate(view(p), view(n), canopy, PlanMethod::Shells, {2.0f}, got.data());
  ao_canopy_shells(view(p), view(n), t.shells, CanopyOptions{2.0f, 0.1f}, ShellCombine::Product,
                   want.data());
  int held = 0;
  for (std::size_t i = 0; i < count; ++i) {
    bool inside = false;
    for (const Ellipsoid& s : t.shells) inside = inside || s.contains(view(p)[i]);
    if (!inside) continue;  // float32 rounding put it outside: not this test's case
    ++held;
    EXPECT_EQ(got[i], want[i]) << "point " << i;
  }
  EXPECT_GT(held, 300);
}

namespace {

// A footprint: the cells of a ring-shaped field (a hole in the middle) of cell size h.
GrassCoverData ring_cover(double h, double blade) {
  GrassCoverData d;
  d.ground = 0.25;
  d.blade = blade;
  d.visibility = 0.3;
  d.cell = h;
  d.origin_x = -3.0;
  d.origin_y = -2.0;
  d.width = 40;
  for (std::int64_t i = 1; i < 30; ++i) {
    for (std::int64_t j = 1; j < 39; ++j) {
      const double r = std::hypot(double(i) - 15.0, double(j) - 20.0);
      if (r > 4.0 && r < 12.0) d.keys.push_back(i * d.width + j);
    }
  }
  return d;
}

// The cover's law the way core/grass_layer.py wrote it: every disc offset looked up.
float cover_by_offsets(const GrassCoverData& d, Vec3 x) {
  if (!(std::fabs(double(x.z) - d.ground) <= d.blade)) return 1.0f;
  const auto m = std::max<std::int64_t>(1, std::int64_t(std::ceil(d.blade / d.cell)));
  const auto i = std::int64_t(std::floor((double(x.x) - d.origin_x) / d.cell));
  const auto j = std::int64_t(std::floor((double(x.y) - d.origin_y) / d.cell));
  double hits = 0;
  long total = 0;
  for (std::int64_t di = -m; di <= m; ++di) {
    for (std::int64_t dj = -m; dj <= m; ++dj) {
      if (di * di + dj * dj > m * m) continue;
      ++total;
      const std::int64_t jj = j + dj;
      if (i + di < 0 || jj < 0 || jj >= d.width) continue;
      hits += std::binary_search(d.keys.begin(), d.keys.end(), (i + di) * d.width + jj);
    }
  }
  return static_cast<float>(1.0 - (hits / double(total)) * (1.0 - d.visibility));
}

}  // namespace

TEST(GrassCover, EqualsTheDiscCountedOffsetByOffset) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0, 1);
  for (const double blade : {0.05, 0.4, 1.3}) {  // m = 1, 2 and 7 cells
    const GrassCoverData d = ring_cover(0.2, blade);
    const GrassCover cover(d);
    std::vector<float> p, n;
    for (int k = 0; k < 3000; ++k) {
      test::add(p, -3.0f + 6.0f * u(rng), -1.0f + 6.0f * u(rng),
                float(d.ground + d.blade * (2.4 * u(rng) - 1.2)));
    }
    std::vector<float> got(p.size() / 3);
    cover.ground_visibility(view(p), got.data());
    int inside = 0, edge = 0;
    for (std::size_t k = 0; k < got.size(); ++k) {
      const float want = cover_by_offsets(d, view(p)[k]);
      ASSERT_EQ(got[k], want) << "blade " << blade << " point " << k;
      inside += got[k] == 0.3f;
      edge += got[k] > 0.3f && got[k] < 1.0f;
    }
    // Every case is reached: inside (a disc narrower than the ring), at the edge, away.
    if (blade < 1.0) EXPECT_GT(inside, 50) << "blade " << blade;
    EXPECT_GT(edge, 50) << "blade " << blade;
  }
  // Far points (any cell index) see 1.
  const GrassCover cover(ring_cover(0.2, 0.4));
  EXPECT_EQ(cover.visibility({1e9f, -1e9f, 0.25f}), 1.0f);
  EXPECT_EQ(cover.visibility({0.0f, 0.0f, 1e9f}), 1.0f);
}

TEST(GrassCover, BadDataThrows) {
  const GrassCoverData good = ring_cover(0.2, 0.4);
  auto with = [&](auto change) {
    GrassCoverData d = good;
    change(d);
    return d;
  };
  EXPECT_NO_THROW(GrassCover{good});
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.blade = 0; })}, std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.cell = NAN; })}, std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.visibility = 1.5; })},
               std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.ground = INFINITY; })},
               std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.width = 0; })}, std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { std::swap(d.keys[0], d.keys[1]); })},
               std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.keys[0] = -1; })},
               std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.keys.back() = std::int64_t{1} << 60; })},
               std::invalid_argument);
  EXPECT_THROW(GrassCover{with([](GrassCoverData& d) { d.blade = 1e7 * d.cell; })},
               std::invalid_argument);  // a disc of more than 2^20 cells across
}

TEST(ForestOccluders, IsTheProductOfOneFieldPerPrototypeAndOneForTheTrunks) {
  const std::vector<Ellipsoid> oaks = {ball(2, 0, 3, 1), ball(-3, 1, 3, 1.2f)};
  const std::vector<Ellipsoid> pines = {ball(0, 3, 4, 0.8f)};
  const std::vector<Ellipsoid> trunks = {ball(2, 0, 1, 0.2f), ball(0, 3, 1, 0.2f)};
  const ForestOccluders forest({{oaks, 0.8f}, {{}, 2.0f}, {pines, 2.5f}}, trunks, 1e-3f, 6.0f);
  EXPECT_EQ(forest.shells(), 3u);
  EXPECT_EQ(forest.solids(), 2u);
  OccluderOptions o;
  o.distance = 6.0f;
  o.tau = 0.8f;
  const OccluderField f_oaks(oaks, o);
  o.tau = 2.5f;
  const OccluderField f_pines(pines, o);
  o.solid = true;
  const OccluderField f_trunks(trunks, o);
  EXPECT_EQ(forest.max_candidates(),
            f_oaks.max_candidates() + f_pines.max_candidates() + f_trunks.max_candidates());
  std::vector<float> p, n;
  scatter(p, n, 1000, 9);
  std::vector<float> got(p.size() / 3);
  forest.ao(view(p), view(n), got.data());
  int darker = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const Vec3 x = view(p)[i], nv = view(n)[i];
    float want = 1.0f;
    want *= f_oaks.visibility(x, nv);
    want *= f_pines.visibility(x, nv);
    want *= f_trunks.visibility(x, nv);
    ASSERT_EQ(got[i], want) << "point " << i;
    darker += got[i] < 0.99f;
  }
  EXPECT_GT(darker, 100);
  EXPECT_THROW(ForestOccluders({{oaks, -1.0f}}, {}), std::invalid_argument);
  EXPECT_THROW(ForestOccluders({{oaks, 1.0f}}, {}, 1.0f), std::invalid_argument);
  EXPECT_THROW(ForestOccluders({}, {}, 1e-3f, 0.0f), std::invalid_argument);
}

TEST(ScenePlan, GroundTimesItsGrassCoversAndEveryRoleTimesTheAttachedForest) {
  const std::vector<TreeProxies> trees = {tree_at(-0.8f), tree_at(0.8f)};
  const GrassCover cover(ring_cover(0.2, 0.4));
  ScenePlan plan(trees, ScenePlanOptions{}, {cover, GrassCover(ring_cover(0.3, 0.2))});
  const ScenePlan bare(trees, ScenePlanOptions{});
  EXPECT_EQ(plan.grass_covers(), 2u);
  auto forest = std::make_shared<const ForestOccluders>(
      std::vector<ForestCrowns>{{{ball(3, 0, 3, 1.5f)}, 1.2f}},
      std::vector<Ellipsoid>{ball(3, 0, 1, 0.3f)});
  std::vector<float> p, n;
  scatter(p, n, 2000, 4);
  for (std::size_t i = 0; i < p.size(); i += 3) p[i + 2] = 0.25f + 0.5f * (p[i + 2] - 2.5f);
  const std::size_t count = p.size() / 3;
  const std::vector<float> tau = {0.9f, 1.7f};
  PlanReceivers ground, canopy;
  canopy.role = ReceiverRole::Canopy;
  canopy.tree = 1;
  std::vector<float> plain(count), covered(count), with_forest(count), alone(count),
      cover_a(count), cover_b(count), trees_only(count), canopy_forest(count);
  bare.evaluate(view(p), view(n), ground, PlanMethod::Medium, tau, plain.data());
  plan.evaluate(view(p), view(n), ground, PlanMethod::Medium, tau, covered.data());
  cover.ground_visibility(view(p), cover_a.data());
  GrassCover(ring_cover(0.3, 0.2)).ground_visibility(view(p), cover_b.data());
  EXPECT_EQ(plan.forest(), nullptr);
  plan.set_forest(forest);
  EXPECT_EQ(plan.forest(), forest);
  plan.evaluate(view(p), view(n), ground, PlanMethod::Medium, tau, with_forest.data());
  forest->ao(view(p), view(n), alone.data());
  bare.evaluate(view(p), view(n), canopy, PlanMethod::Medium, tau, trees_only.data());
  plan.evaluate(view(p), view(n), canopy, PlanMethod::Medium, tau, canopy_forest.data());
  int shaded = 0, under_grass = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const float c = std::clamp(plain[i] * cover_a[i] * cover_b[i], 0.0f, 1.0f);
    ASSERT_EQ(covered[i], c) << "point " << i;
    ASSERT_EQ(with_forest[i], std::clamp(c * alone[i], 0.0f, 1.0f)) << "point " << i;
    ASSERT_EQ(canopy_forest[i], std::clamp(trees_only[i] * alone[i], 0.0f, 1.0f));
    shaded += alone[i] < 0.99f;
    under_grass += cover_a[i] < 1.0f;
  }
  EXPECT_GT(shaded, 100);
  EXPECT_GT(under_grass, 100);
  plan.set_forest(nullptr);
  plan.evaluate(view(p), view(n), ground, PlanMethod::Medium, tau, with_forest.data());
  EXPECT_EQ(with_forest, covered);
}

// Receivers the trees' part lights with one kernel alone (one crown holding all of them, or no
// tree at all) still get the grass covers and the forest.
TEST(ScenePlan, CoversAndForestReachReceiversOfOneCrownOrOfNoTree) {
  // A ring inside the crown's shells (so the one-crown shortcut runs), and one around the
  // grass for the no-tree case.
  std::vector<float> p, n, pg, ng;
  for (int i = 0; i < 300; ++i) {
    const float a = 0.07f * i;
    test::add(p, 0.4f * std::cos(a), 0.4f * std::sin(a), 3.0f + 0.3f * std::sin(2 * a));
    test::add(pg, 0.5f * std::cos(a), 0.5f * std::sin(a), 2.8f + 0.4f * std::sin(2 * a));
    test::add(n, std::cos(a), std::sin(a), 0.3f);
  }
  ng = n;
  const std::size_t count = p.size() / 3;
  const TreeProxies tree = tree_at(0.0f);
  for (std::size_t i = 0; i < count; ++i) ASSERT_TRUE(in_crown(tree, view(p)[i])) << i;
  auto forest = std::make_shared<const ForestOccluders>(
      std::vector<ForestCrowns>{{{ball(2.2f, 0, 3, 1.0f)}, 2.0f}},
      std::vector<Ellipsoid>{ball(-2.0f, 0, 1.5f, 0.4f)});
  std::vector<float> shade(count), bare(count), got(count), shade_g(count);
  forest->ao(view(p), view(n), shade.data());
  forest->ao(view(pg), view(ng), shade_g.data());
  PlanReceivers own;
  own.role = ReceiverRole::Canopy;
  own.tree = 0;
  ScenePlan one({tree}, ScenePlanOptions{});
  one.evaluate(view(p), view(n), own, PlanMethod::Shells, {1.2f}, bare.data());
  one.set_forest(forest);
  one.evaluate(view(p), view(n), own, PlanMethod::Shells, {1.2f}, got.data());
  int shaded = 0;
  for (std::size_t i = 0; i < count; ++i) {
    ASSERT_EQ(got[i], std::clamp(bare[i] * shade[i], 0.0f, 1.0f)) << "point " << i;
    shaded += shade[i] < 0.99f;
  }
  EXPECT_GT(shaded, 100);

  // No tree: a ground point sees its grass covers and the forest alone.
  GrassCoverData d;
  d.ground = 2.8;
  d.blade = 0.5;
  d.visibility = 0.25;
  d.cell = 0.25;
  d.origin_x = d.origin_y = -1.0;
  d.width = 8;
  for (std::int64_t k = 0; k < 64; ++k) d.keys.push_back(k);  // the square [-1, 1]²
  const GrassCover cover(d);
  ScenePlan none({}, ScenePlanOptions{}, {cover});
  none.set_forest(forest);
  none.evaluate(view(pg), view(ng), PlanReceivers{}, PlanMethod::Medium, {}, got.data());
  int covered = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const float c = cover.visibility(view(pg)[i]);
    ASSERT_EQ(got[i], std::clamp(c * shade_g[i], 0.0f, 1.0f)) << "point " << i;
    covered += c < 1.0f;
  }
  EXPECT_GT(covered, 100);
}
