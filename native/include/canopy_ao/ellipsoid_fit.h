// Canopy AO — minimum-volume enclosing ellipsoid of a point cloud (docs/DESIGN.md, 'The method
// ladder', 'Fitting the proxies').
//
// Method "khachiyan": Khachiyan's barycentric coordinate-ascent for the minimum-volume enclosing
// ellipsoid (L. G. Khachiyan, "Rounding of polytopes in the real number model of computation",
// Math. Oper. Res. 21, 1996), with Todd & Yildirim's away steps ("On Khachiyan's algorithm for
// the computation of minimum-volume enclosing ellipsoids", Discrete Appl. Math. 155, 2007). It
// stops when every point's Mahalanobis value is ≤ (d+1)(1 + tolerance) and every weighted
// point's is ≥ (d+1)(1 − tolerance): then the ellipsoid is within a factor (1 + tolerance)^{d/2}
// of the optimal volume. It runs on an active set: the extreme points of a deterministic
// stride subsample (≤ max_points points) along fixed directions, grown with the subsample's
// worst violators until none is left; the result is then scaled so that it contains every
// input point (the farthest lies on the surface).
// Method "pca": axes = eigenvectors of the covariance, centre = the box centre in that frame,
// radii ∝ the box half-extents, scaled by one factor so that every point is inside.
// Method "auto": Khachiyan, replaced by the PCA ellipsoid when that has the smaller volume
// (Khachiyan stopped by max_iterations) or Khachiyan failed numerically.
//
// All in double, in the PCA frame normalised by the box half-extents (well conditioned for
// any scale or offset of the input).
//
// Degenerate input (documented, always finite):
//  - an axis is degenerate when its half-extent in the PCA frame is ≤ 1e-3 × the largest;
//    the fit runs in the remaining d ∈ {1, 2} dimensions (a flat patch → minimum-area ellipse,
//    collinear points → the extreme segment) and degenerate axes get radius 0 before clamping;
//  - then every radius is clamped to ≥ min_radius_ratio × the largest radius (default 1e-2: a
//    flat leaf becomes an ellipsoid 1% as thick as it is wide) and to ≥ min_proxy_radius(centre);
//  - one point / all duplicates: a sphere of radius min_proxy_radius(point) = 1e-6·(|p| + 1),
//    identity axes.
// Output: orthonormal right-handed axes sorted by decreasing radius, radii > 0, finite; every
// (kept) input point satisfies |to_unit(p)| ≤ 1 in double (radii are inflated by a relative 1e-6
// and rounded up to float to make that hold after rounding).
#pragma once

#include <cstddef>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

// === Options
enum class EllipsoidMethod { Auto, Khachiyan, Pca };

struct EllipsoidFitOptions {
  /// Fraction in [0, 0.5) of points ignored as outliers (see ellipsoid_trimmed_indices).
  double trim = 0.0;
  EllipsoidMethod method = EllipsoidMethod::Auto;
  /// Khachiyan's relative tolerance, in (0, 1): volume within (1 + tolerance)^{d/2} of optimal
  /// on the subsample, before the final containment scaling.
  double tolerance = 1e-3;
  /// Khachiyan runs on at most this many points (a stride subsample); ≥ 4.
  std::size_t max_points = 20000;
  /// Smallest radius as a fraction of the largest, in (0, 1].
  double min_radius_ratio = 1e-2;
  /// Cap on Khachiyan iterations per active-set round.
  int max_iterations = 20000;
};

/// What the fit did (for tests and reports).
struct EllipsoidFitInfo {
  EllipsoidMethod method_used = EllipsoidMethod::Pca;
  int dimension = 3;         ///< intrinsic dimension found: 0 (a point), 1, 2 or 3
  int iterations = 0;        ///< Khachiyan iterations, all rounds
  bool converged = false;    ///< Khachiyan met its tolerance
  std::size_t active_points = 0;
  double containment_scale = 1;  ///< factor applied to Khachiyan's radii to contain all points
};

/// What a Khachiyan fit leaves for the next fit of the same points moved a little (live AO's
/// frames): the support points (indices into the stride subsample) and their weights. A fit
/// given one starts Khachiyan from those weights instead of from the extreme points with equal
/// weights: it stops at the same tolerance in a fraction of the iterations (the optimum moves
/// little between frames), so its ellipsoid is within the tolerance of a fresh fit's, not bit
/// for bit the same. A state from a different point count, subsample or dimension is ignored
/// (a fresh fit); the fit then refills it.
struct EllipsoidWarmStart {
  std::size_t points = 0, pool = 0;  ///< the fit's point and subsample counts
  int dimension = 0;
  std::vector<int> active;           ///< subsample indices with weight > 0
  std::vector<double> weights;       ///< their weights (sum 1)
};

// === Fitting
/// Minimum-volume enclosing ellipsoid of `points` (N ≥ 1, finite). See the file comment.
/// Throws std::invalid_argument: N == 0, non-finite coordinates, trim outside [0, 0.5),
/// tolerance outside (0, 1), max_points < 4, min_radius_ratio outside (0, 1].
/// warm: null, or a state read (when it fits) and rewritten (EllipsoidWarmStart).
Ellipsoid fit_min_ellipsoid(PointsView points, const EllipsoidFitOptions& options = {},
                            EllipsoidFitInfo* info = nullptr,
                            EllipsoidWarmStart* warm = nullptr);

/// The same on points[indices] only (indices non-empty, each < points.size); options.trim is
/// not applied here (the caller chose the points).
Ellipsoid fit_min_ellipsoid(PointsView points, const std::vector<std::size_t>& indices,
                            const EllipsoidFitOptions& options = {},
                            EllipsoidFitInfo* info = nullptr,
                            EllipsoidWarmStart* warm = nullptr);

/// Indices (ascending) kept by the ellipsoid's percentile trim: a first Euclidean trim about the
/// coordinate-wise median (trimmed_indices) gives a robust mean and covariance; then the
/// floor(trim·N) points with the largest Mahalanobis distance under those are dropped (so an
/// elongated canopy is trimmed evenly around, not at its ends). Covariance eigenvalues are
/// floored at 1e-4 × the largest (flat input). Ties broken by index.
std::vector<std::size_t> ellipsoid_trimmed_indices(PointsView points, double trim);

// === Checks
/// True if every point satisfies |to_unit(p)|² ≤ 1 + rel_tol, evaluated in double.
bool contains_all(const Ellipsoid& e, PointsView points, double rel_tol = 0.0);
/// max over points of |to_unit(p)|² (≤ 1 iff all inside), in double.
double max_unit_norm2(const Ellipsoid& e, PointsView points);

/// Eigen-decomposition of a symmetric n×n matrix (n ≤ 3, row-major a[i][j]) by cyclic Jacobi:
/// eigenvalues descending in w, eigenvector k in column k of v. Shared with the shell fitter.
void symmetric_eigen(int n, const double a[3][3], double w[3], double v[3][3]);

}  // namespace canopy_ao
