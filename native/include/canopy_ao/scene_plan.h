// Canopy AO — the scene plan: every tree's fitted proxies and trunks, with their occluder
// grids, built once per bake and evaluated for any set of receivers (docs/DESIGN.md, 'How each
// role is lit' and 'Data flow').
//
// The composition, for receivers of one role (the analytic rungs: sphere, ellipsoid,
// Reeves–Blau, shells, medium):
//  - A receiver inside a crown's shells (Ellipsoid::contains, |x'|² ≤ 1 + 1e-5) — its own
//    canopy, a trunk, but also ground or grass a low crown reaches down to — gets that crown's
//    in-shell model (canopy_model.h, reeves_blau.h, medium_table.h), with that tree's τ. A
//    receiver inside several crowns (interlocking trees) takes the first tree's, in the
//    plan's tree order; the others then occlude it.
//  - Every other tree's shells occlude it (occluders.h, medium law, each tree's τ; shells it
//    is inside of are skipped there); a receiver inside no crown sees every tree's shells.
//  - Trunks are solid occluders (opacity 1), except a CANOPY or TRUNK receiver's own tree's
//    (which its leaves and bark sit inside or on).
//  - GRASS receivers: times the grass law (grass.h: the field's blade layer, or Hegeman's Eq. 9)
//    with the given ground and blade height.
//  - The product, clipped to [0, 1]. V = Π (1 − occ) over independent occluders, so the order
//    of the factors only changes round-off.
//  - GROUND receivers: times each grass field's cover over the ground (grass_cover.h), in the
//    plan's order, clipped again.
//  - Every receiver: times the instanced forest (forest.h), if one is attached, clipped again.
//    It is attached (or replaced) after construction, without rebuilding the trees' grids: the
//    forest may come after the plan (core/bake.py, attach_forest).
// Which shells a method lights with: sphere → each crown's sphere; ellipsoid, reeves_blau →
// its ellipsoid; shells, medium → its k shells. The occluder grids (one per shell set, one for
// the trunks) depend on the shells, ε and the AO distance only, so they are built once here and
// τ is an argument of evaluate (calibration's search calls it many times). The shells'
// material at a τ (the medium table's slice, 36 kB to make) is kept for the last few τ seen,
// so a search that moves one tree's τ does not remake every other tree's.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "canopy_ao/forest.h"
#include "canopy_ao/geometry.h"
#include "canopy_ao/grass.h"
#include "canopy_ao/grass_cover.h"
#include "canopy_ao/occluders.h"

namespace canopy_ao {

/// One tree: its crown's proxies (if it has leaves) and its solid trunks (may be empty).
struct TreeProxies {
  bool has_crown = false;
  Sphere sphere;                  ///< crown (has_crown): the fitted sphere
  Ellipsoid ellipsoid;            ///< crown: the fitted ellipsoid
  std::vector<Ellipsoid> shells;  ///< crown: the k shells (≥ 1)
  std::vector<Ellipsoid> trunks;  ///< solid ellipsoids fitted to the trunk's bole
};

enum class PlanMethod { Sphere, Ellipsoid, ReevesBlau, Shells, Medium };
enum class ReceiverRole { Canopy, Trunk, Ground, Grass };

struct ScenePlanOptions {
  /// AO distance D (> 0; +inf = unlimited), occluders.h's meaning.
  float distance = std::numeric_limits<float>::infinity();
  /// Occluders' cut-off ε in [0, 1) (occluders.h).
  float epsilon = 1e-3f;
};

/// What the receivers of one evaluate call are.
struct PlanReceivers {
  ReceiverRole role = ReceiverRole::Ground;
  /// The receivers' tree: index into the plan's trees, or −1 (none, or not in the plan).
  std::int32_t tree = -1;
  /// Optional per-receiver tree (N entries, each −1 or a tree index); overrides `tree`.
  const std::int32_t* trees = nullptr;
  /// Role Grass: the grass law's ground level, blade height and layer (required for that role).
  GrassOptions grass;
};

class ScenePlan {
 public:
  // === Constructor
  /// PRE: every crown's sphere, ellipsoid and shells valid (shells non-empty), trunks valid,
  /// options valid. Throws std::invalid_argument otherwise. No trees is allowed (AO 1, times
  /// the grass law, the grass covers and the forest). covers: the grass fields over the ground.
  ScenePlan(std::vector<TreeProxies> trees, const ScenePlanOptions& options,
            std::vector<GrassCover> covers = {});

  // === Methods
  /// AO of N receivers (positions, normals N×3; zero normals as the kernels treat them) lit by
  /// `method`; tau: one τ per tree (each in [0, ∞), finite). out: N floats in [0, 1].
  /// Throws std::invalid_argument: tau of the wrong size or invalid, a tree index out of range,
  /// bad grass options for role Grass.
  void evaluate(PointsView positions, PointsView normals, const PlanReceivers& receivers,
                PlanMethod method, const std::vector<float>& tau, float* out) const;

  /// Attaches the instanced forest every receiver is then multiplied by (nullptr: none).
  /// Safe while another thread evaluates: that call keeps the forest it started with.
  void set_forest(std::shared_ptr<const ForestOccluders> forest);

  // === Introspection
  std::size_t trees() const { return trees_.size(); }
  std::size_t grass_covers() const { return covers_.size(); }
  std::shared_ptr<const ForestOccluders> forest() const;
  /// The shells `method` lights tree t with (and that occlude for it); empty without a crown.
  const std::vector<Ellipsoid>& shells(std::size_t t, PlanMethod method) const;
  /// Largest number of candidate occluders one receiver tests for `method` (crowns + trunks).
  std::size_t max_candidates(PlanMethod method) const;

 private:
  static int set_of(PlanMethod m);  // 0 sphere, 1 ellipsoid, 2 shells
  // evaluate without the grass covers and the forest (evaluate multiplies them after it).
  void evaluate_trees(PointsView positions, PointsView normals, const PlanReceivers& r,
                      PlanMethod method, const std::vector<float>& tau, float* out) const;
  std::shared_ptr<const OccluderMaterial> material(float tau) const;

  std::vector<TreeProxies> trees_;
  std::vector<std::vector<Ellipsoid>> sets_[3];  // per shell set, per tree: its shells
  // Per shell set, per tree: a sphere holding its shells (centre, squared radius with slack;
  // −1 without shells), so finding a receiver's crown skips far trees cheaply.
  std::vector<std::pair<Vec3, float>> bounds_[3];
  std::vector<OccluderField> crowns_;            // per shell set: every crown, grouped by tree
  OccluderField trunks_;                         // every trunk (solid), grouped by tree
  std::vector<GrassCover> covers_;               // over the ground, in order
  mutable std::mutex forest_mutex_;              // guards forest_
  std::shared_ptr<const ForestOccluders> forest_;
  mutable std::mutex cache_mutex_;               // guards materials_ (evaluate is const)
  mutable std::vector<std::pair<float, std::shared_ptr<const OccluderMaterial>>> materials_;
};

}  // namespace canopy_ao
