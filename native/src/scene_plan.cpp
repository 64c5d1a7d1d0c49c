#include "canopy_ao/scene_plan.h"

#include <algorithm>
#include <string>
#include <utility>

#include "canopy_ao/canopy_model.h"
#include "canopy_ao/medium_table.h"
#include "canopy_ao/model_checks.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/reeves_blau.h"

namespace canopy_ao {

namespace {

// Every tree's shells of one set in one list, each tagged with its tree (the group).
OccluderField grouped_field(const std::vector<std::vector<Ellipsoid>>& by_tree, bool solid,
                            const ScenePlanOptions& o) {
  std::vector<Ellipsoid> all;
  std::vector<std::int32_t> groups;
  for (std::size_t t = 0; t < by_tree.size(); ++t) {
    for (const Ellipsoid& e : by_tree[t]) {
      all.push_back(e);
      groups.push_back(static_cast<std::int32_t>(t));
    }
  }
  OccluderOptions opt;
  opt.epsilon = o.epsilon;
  opt.solid = solid;
  opt.law = OccluderLaw::Medium;  // the shells' law; solid trunks ignore it
  opt.distance = o.distance;
  return OccluderField(std::move(all), opt, std::move(groups));
}

std::vector<std::vector<Ellipsoid>> trunks_of(const std::vector<TreeProxies>& trees) {
  std::vector<std::vector<Ellipsoid>> out;
  for (const TreeProxies& t : trees) out.push_back(t.trunks);
  return out;
}

std::vector<TreeProxies> checked(std::vector<TreeProxies> trees) {
  for (std::size_t t = 0; t < trees.size(); ++t) {
    const TreeProxies& p = trees[t];
    if (!p.has_crown) continue;
    check_sphere(p.sphere);
    check_ellipsoid(p.ellipsoid);
    if (p.shells.empty()) {
      throw std::invalid_argument("tree " + std::to_string(t) + " has a crown but no shells");
    }
  }
  return trees;  // shells and trunks: checked by the occluder fields
}

// In-shell model of one crown for its claimed receivers (docs/DESIGN.md, 'The method ladder').
// `medium`: the material at τ (its slice serves the medium rung).
void in_shell(PointsView p, PointsView n, const TreeProxies& t, PlanMethod m, float tau,
              const OccluderMaterial& medium, float* out) {
  const CanopyOptions opt{tau, 0.1f};
  switch (m) {
    case PlanMethod::Sphere: return ao_canopy_sphere(p, n, t.sphere, opt, out);
    case PlanMethod::Ellipsoid: return ao_canopy_ellipsoid(p, n, t.ellipsoid, opt, out);
    case PlanMethod::ReevesBlau: return ao_reeves_blau(p, t.ellipsoid, tau, out);
    case PlanMethod::Shells:
      if (t.shells.size() == 1) return ao_canopy_ellipsoid(p, n, t.shells[0], opt, out);
      return ao_canopy_shells(p, n, t.shells, opt, ShellCombine::Product, out);
    case PlanMethod::Medium:
      return ao_medium_shells_sliced(p, n, t.shells, {&medium.slice}, MediumCombine::Product,
                                     out);
  }
}

// A sphere holding every shell (each within its largest radius of its centre), its squared
// radius grown by 1e-3: far more than Ellipsoid::contains' slack (|x'|² ≤ 1 + 1e-5) and float
// round-off, so a point outside it is outside every shell. −1: no shells.
std::pair<Vec3, float> bound(const std::vector<Ellipsoid>& shells) {
  if (shells.empty()) return {Vec3{0, 0, 0}, -1.0f};
  double c[3] = {0, 0, 0};
  for (const Ellipsoid& e : shells) {
    for (int k = 0; k < 3; ++k) c[k] += double(e.center[k]) / double(shells.size());
  }
  const Vec3 cf{float(c[0]), float(c[1]), float(c[2])};  // the radius is measured from it
  double r = 0;
  for (const Ellipsoid& e : shells) {
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
      d2 += (double(e.center[k]) - double(cf[k])) * (double(e.center[k]) - double(cf[k]));
    }
    const double rmax = std::max({e.radii.x, e.radii.y, e.radii.z});
    r = std::max(r, std::sqrt(d2) + rmax);
  }
  r *= 1.001;
  return {cf, float(r * r)};
}

}  // namespace

int ScenePlan::set_of(PlanMethod m) {
  switch (m) {
    case PlanMethod::Sphere: return 0;
    case PlanMethod::Ellipsoid:
    case PlanMethod::ReevesBlau: return 1;
    default: return 2;
  }
}

ScenePlan::ScenePlan(std::vector<TreeProxies> trees, const ScenePlanOptions& options,
                     std::vector<GrassCover> covers)
    : trees_(checked(std::move(trees))),  // moved, not copied; trunks_ follows trees_
      trunks_(grouped_field(trunks_of(trees_), /*solid=*/true, options)),
      covers_(std::move(covers)) {
  for (const TreeProxies& t : trees_) {
    sets_[0].push_back(t.has_crown ? std::vector<Ellipsoid>{Ellipsoid::from_sphere(t.sphere)}
                                   : std::vector<Ellipsoid>{});
    sets_[1].push_back(t.has_crown ? std::vector<Ellipsoid>{t.ellipsoid}
                                   : std::vector<Ellipsoid>{});
    sets_[2].push_back(t.has_crown ? t.shells : std::vector<Ellipsoid>{});
  }
  for (int k = 0; k < 3; ++k) {
    crowns_.push_back(grouped_field(sets_[k], /*solid=*/false, options));
    for (const std::vector<Ellipsoid>& shells : sets_[k]) bounds_[k].push_back(bound(shells));
  }
}

void ScenePlan::set_forest(std::shared_ptr<const ForestOccluders> forest) {
  std::lock_guard<std::mutex> lock(forest_mutex_);
  forest_ = std::move(forest);
}

std::shared_ptr<const ForestOccluders> ScenePlan::forest() const {
  std::lock_guard<std::mutex> lock(forest_mutex_);
  return forest_;
}

std::shared_ptr<const OccluderMaterial> ScenePlan::material(float tau) const {
  std::lock_guard<std::mutex> lock(cache_mutex_);
  for (const auto& [t, m] : materials_) {
    if (t == tau) return m;
  }
  OccluderOptions o;
  o.tau = tau;
  auto m = std::make_shared<const OccluderMaterial>(OccluderMaterial::of(o));
  // Room for every tree's τ and a search's few trial values; the oldest goes first.
  if (materials_.size() >= 2 * trees_.size() + 8) materials_.erase(materials_.begin());
  materials_.emplace_back(tau, m);
  return m;
}

const std::vector<Ellipsoid>& ScenePlan::shells(std::size_t t, PlanMethod method) const {
  return sets_[set_of(method)].at(t);
}

std::size_t ScenePlan::max_candidates(PlanMethod method) const {
  return crowns_[set_of(method)].max_candidates() + trunks_.max_candidates();
}

void ScenePlan::evaluate_trees(PointsView positions, PointsView normals, const PlanReceivers& r,
                               PlanMethod method, const std::vector<float>& tau,
                               float* out) const {
  check_receivers(positions, normals);
  const std::size_t n_trees = trees_.size();
  if (tau.size() != n_trees) {
    throw std::invalid_argument("tau must hold one value per tree (" + std::to_string(n_trees) +
                                "), got " + std::to_string(tau.size()));
  }
  for (float t : tau) check_tau(t);
  auto bad_tree = [&](std::int32_t t) {
    return t < -1 || (t >= 0 && static_cast<std::size_t>(t) >= n_trees);
  };
  if (r.trees == nullptr && bad_tree(r.tree)) {
    throw std::invalid_argument("tree " + std::to_string(r.tree) + " is not in the plan's " +
                                std::to_string(n_trees) + " trees (-1 = none)");
  }
  if (r.trees != nullptr) {
    for (std::size_t i = 0; i < positions.size; ++i) {
      if (bad_tree(r.trees[i])) {
        throw std::invalid_argument("trees[" + std::to_string(i) + "] = " +
                                    std::to_string(r.trees[i]) + " is not in the plan's " +
                                    std::to_string(n_trees) + " trees (-1 = none)");
      }
    }
  }
  const std::size_t n = positions.size;
  std::vector<float> grass;
  if (r.role == ReceiverRole::Grass) {  // checks the grass options before any work
    grass.resize(n);
    ao_grass(positions, normals, r.grass, grass.data());
  }
  if (n == 0) return;

  // Materials per tree (the medium table's slice at its τ), made outside the parallel loops.
  const int set = set_of(method);
  const std::vector<std::vector<Ellipsoid>>& shells = sets_[set];
  std::vector<std::shared_ptr<const OccluderMaterial>> held(n_trees);
  std::vector<const OccluderMaterial*> crown_law(n_trees, nullptr);
  for (std::size_t t = 0; t < n_trees; ++t) {
    if (shells[t].empty()) continue;
    held[t] = material(tau[t]);
    crown_law[t] = held[t].get();
  }

  // Which crown claims each receiver: the first tree (plan order) with a shell holding it.
  // Ellipsoid::contains with each axis divided by its radius once, not per receiver (the
  // same test up to the last bit of a double, far inside its 1e-5 slack).
  struct Inside {
    double c[3], a[3][3];
    bool operator()(Vec3 p) const {
      const double d[3] = {double(p.x) - c[0], double(p.y) - c[1], double(p.z) - c[2]};
      double u2 = 0;
      for (int k = 0; k < 3; ++k) {
        const double u = a[k][0] * d[0] + a[k][1] * d[1] + a[k][2] * d[2];
        u2 += u * u;
      }
      return u2 <= 1 + 1e-5;
    }
  };
  std::vector<std::vector<Inside>> inside(n_trees);
  for (std::size_t t = 0; t < n_trees; ++t) {
    for (const Ellipsoid& e : shells[t]) {
      Inside in{{double(e.center.x), double(e.center.y), double(e.center.z)}, {}};
      for (int k = 0; k < 3; ++k) {
        const double r = double(e.radii[k]);
        in.a[k][0] = e.axes[k].x / r;
        in.a[k][1] = e.axes[k].y / r;
        in.a[k][2] = e.axes[k].z / r;
      }
      inside[t].push_back(in);
    }
  }
  std::vector<std::int32_t> claim(n);
  parallel_for_blocks(n, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Vec3 x = positions[i];
      std::int32_t c = -1;
      for (std::size_t t = 0; t < n_trees && c < 0; ++t) {
        const Vec3 d = x - bounds_[set][t].first;
        if (!(dot(d, d) <= bounds_[set][t].second)) continue;  // also no shells (−1)
        for (const Inside& in : inside[t]) {
          if (in(x)) {
            c = static_cast<std::int32_t>(t);
            break;
          }
        }
      }
      claim[i] = c;
    }
  });

  // In-shell models, per claiming tree (each kernel runs in parallel over its receivers).
  std::fill(out, out + n, 1.0f);
  std::vector<std::size_t> count(n_trees + 1, 0);
  for (std::int32_t c : claim) ++count[static_cast<std::size_t>(c + 1)];
  // The receivers grouped by claiming tree, ascending within each (one counting sort, not a
  // scan of every receiver per tree): tree t's are order[start[t + 1] .. start[t + 2]).
  std::vector<std::size_t> start(n_trees + 2, 0), order;
  for (std::size_t t = 0; t <= n_trees; ++t) start[t + 1] = start[t] + count[t];
  std::vector<float> pbuf, nbuf, vbuf;
  for (std::size_t t = 0; t < n_trees; ++t) {
    const std::size_t m = count[t + 1];
    if (m == 0) continue;
    if (m == n) {  // one crown holds every receiver (its own leaves): no copies
      in_shell(positions, normals, trees_[t], method, tau[t], *held[t], out);
      continue;
    }
    if (order.empty()) {
      order.resize(n);
      std::vector<std::size_t> fill(start.begin(), start.end() - 1);
      for (std::size_t i = 0; i < n; ++i) {
        order[fill[static_cast<std::size_t>(claim[i] + 1)]++] = i;
      }
    }
    const std::size_t* idx = order.data() + start[t + 1];
    pbuf.resize(3 * m);
    nbuf.resize(3 * m);
    vbuf.resize(m);
    for (std::size_t j = 0; j < m; ++j) {
      std::copy_n(positions.data + 3 * idx[j], 3, pbuf.data() + 3 * j);
      std::copy_n(normals.data + 3 * idx[j], 3, nbuf.data() + 3 * j);
    }
    in_shell({pbuf.data(), m}, {nbuf.data(), m}, trees_[t], method, tau[t], *held[t],
             vbuf.data());
    for (std::size_t j = 0; j < m; ++j) out[idx[j]] = vbuf[j];
  }

  // Every other crown as occluders, then the trunks (solid), the grass law, the clip.
  const bool own_trunks_skipped = r.role == ReceiverRole::Canopy || r.role == ReceiverRole::Trunk;
  const OccluderField& crowns = crowns_[set];
  // The common case of one tree's own leaves needs none of that pass (a third of the bake's
  // evaluate time at 1M receivers): no crown but the claiming one, no trunk that is not the
  // receivers' own, no grass law. The in-shell kernels' values are already in [0, 1].
  std::size_t crowned = 0;
  for (std::size_t t = 0; t < n_trees; ++t) crowned += shells[t].empty() ? 0 : 1;
  const bool one_crown_claims_all =
      crowned == 0 || (crowned == 1 && std::any_of(count.begin() + 1, count.end(),
                                                   [n](std::size_t c) { return c == n; }));
  bool trunks_apply = false;
  for (std::size_t i = 0; i < trunks_.size() && !trunks_apply; ++i) {
    trunks_apply = !(own_trunks_skipped && r.trees == nullptr && trunks_.group(i) == r.tree);
  }
  if (one_crown_claims_all && !trunks_apply && grass.empty()) return;
  parallel_for_blocks(n, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Vec3 x = positions[i], nv = normals[i];
      float v = out[i] * crowns.visibility(x, nv, crown_law.data(), claim[i]);
      const std::int32_t own = r.trees != nullptr ? r.trees[i] : r.tree;
      v *= trunks_.visibility(x, nv, own_trunks_skipped ? own : -1);  // solid: opacity 1
      if (!grass.empty()) v *= grass[i];
      out[i] = std::clamp(v, 0.0f, 1.0f);
    }
  });
}

void ScenePlan::evaluate(PointsView positions, PointsView normals, const PlanReceivers& r,
                         PlanMethod method, const std::vector<float>& tau, float* out) const {
  evaluate_trees(positions, normals, r, method, tau, out);
  // Then the grass covers over a ground point and the forest, each clipped (the order the
  // add-on's Python multiplied them in, so the round-off is the same). A pass of its own: any
  // receiver the trees' part finishes early still gets them.
  const bool covered = r.role == ReceiverRole::Ground && !covers_.empty();
  const std::shared_ptr<const ForestOccluders> forest = this->forest();  // held for the call
  if (!covered && !forest) return;
  parallel_for_blocks(positions.size, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Vec3 x = positions[i];
      float v = out[i];
      if (covered) {
        for (const GrassCover& c : covers_) v *= c.visibility(x);
        v = std::clamp(v, 0.0f, 1.0f);
      }
      if (forest) v = std::clamp(v * forest->visibility(x, normals[i]), 0.0f, 1.0f);
      out[i] = v;
    }
  });
}

}  // namespace canopy_ao
