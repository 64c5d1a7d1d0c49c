// Canopy AO — k shells: cluster the canopy points, fit one proxy per cluster (docs/DESIGN.md,
// 'The method ladder').
//
// Clustering: k-means++ seeding (Arthur & Vassilvitskii, "k-means++: the advantages of careful
// seeding", SODA 2007) from a SplitMix64 stream seeded with `seed` (same seed → same result, on
// any machine and thread count), then Lloyd iterations until no label changes, the summed
// squared centroid shift is ≤ 1e-4 × the points' mean per-axis variance (scikit-learn's
// rule; one more assignment then matches labels to centroids), or max_iterations. The assignment step runs in parallel (each point independently; ties go to
// the lowest cluster index); centroid sums are accumulated serially in double, in point order.
// An emptied cluster is re-seeded at the point farthest from its centroid.
// Fewer distinct points than k: seeding stops when every point is already a centre, so fewer
// clusters come back (empty clusters are dropped and labels renumbered 0..K'-1, K' ≤ k).
// Then each cluster gets a proxy: fit_min_ellipsoid (kind Ellipsoid) or fit_min_sphere
// returned as Ellipsoid::from_sphere (kind Sphere), with the percentile trim applied per
// cluster. A trimmed-away point keeps its cluster's label but may lie outside its shell.
#pragma once

#include <cstdint>
#include <vector>

#include "canopy_ao/ellipsoid_fit.h"
#include "canopy_ao/geometry.h"

namespace canopy_ao {

// === Options
enum class ShellKind { Ellipsoid, Sphere };

struct ShellFitOptions {
  int k = 2;                             ///< clusters asked for, ≥ 1
  ShellKind kind = ShellKind::Ellipsoid;
  double trim = 0.0;                     ///< per-cluster outlier fraction, [0, 0.5)
  std::uint64_t seed = 0;                ///< k-means++ seed
  int max_iterations = 100;              ///< Lloyd iterations cap, ≥ 1
  EllipsoidFitOptions ellipsoid;         ///< for kind Ellipsoid (its trim is replaced by `trim`)
};

// === Result
struct ShellFit {
  std::vector<Ellipsoid> shells;      ///< K' ≤ k proxies (spheres as equal-radii ellipsoids)
  std::vector<std::int32_t> labels;   ///< (N,) cluster of each point, in [0, K')
  std::vector<Vec3> centroids;        ///< (K',) k-means centroids
  int iterations = 0;                 ///< Lloyd iterations run
  bool converged = false;             ///< labels or centroids settled before the cap
};

/// Clusters `points` (N ≥ 1, finite) into at most options.k groups and fits a shell to each.
/// Throws std::invalid_argument: N == 0, non-finite coordinates, k < 1, trim outside
/// [0, 0.5), max_iterations < 1, bad ellipsoid options.
ShellFit fit_shells(PointsView points, const ShellFitOptions& options);

}  // namespace canopy_ao
