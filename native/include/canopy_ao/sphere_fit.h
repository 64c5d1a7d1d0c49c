// Canopy AO — exact minimum enclosing sphere of a point cloud (docs/DESIGN.md, 'Fitting the
// proxies').
//
// Algorithm: Welzl's move-to-front recursion with Gärtner's pivoting and his numerically stable
// incremental "push" of boundary points (B. Gärtner, "Fast and Robust Smallest Enclosing Balls",
// ESA 1999, the Miniball code). Points are visited in a deterministic shuffled order (fixed-seed
// SplitMix64 Fisher-Yates), so the result never depends on the input order's adversities nor on
// the run. The recursion depth is bounded by the dimension (≤ 5 frames), never by N: 10^6
// points are fine. Everything is computed in double.
//
// Robustness: a boundary point that is (numerically) affinely dependent on the current support
// set (duplicates, collinear or coplanar points) is not pushed — in exact arithmetic it could not
// be outside the ball; in floating point it may be outside by round-off. A final pass therefore
// sets the radius to the largest distance from the (float) centre to any input point, and
// inflates it by a relative kSphereInflation = 1e-6, so `contains_all` always holds.
// The returned radius thus exceeds the exact minimum by at most ~1e-6·r + float rounding of the
// centre (≈ 6e-8·|centre|).
#pragma once

#include <cstddef>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

/// Relative inflation of every fitted sphere's radius (see the file comment).
constexpr double kSphereInflation = 1e-6;

/// The smallest radius any fitted proxy gets: 1e-6·(|c| + 1) for a proxy centred at c (world
/// units). Only a single point / all-duplicates input (or a cloud smaller than that) hits it;
/// it keeps R > 0 so the models' divisions by R stay finite, and stays above float round-off
/// of the centre (≈ 6e-8·|c|).
inline double min_proxy_radius(Vec3 c) { return 1e-6 * (double(length(c)) + 1.0); }

/// Rounds a double triple to a float Vec3 — really rounds: GCC 12 at -O2 was seen to
/// SLP-vectorise `double(float(x))` back into `x` (sphere_fit.cpp), which broke the containment
/// certificate computed from the rounded centre. Every fitter rounds through this.
Vec3 round_to_vec3(const double v[3]);

// === Input checks shared by every fitter
/// Throws std::invalid_argument (naming `name`) if points is empty or has a non-finite coord.
void check_fit_points(PointsView points, const char* name = "points");
/// Throws std::invalid_argument unless trim is in [0, 0.5).
void check_trim(double trim);

/// Indices (ascending) of the points kept by a percentile trim: the floor(trim·N) points farthest
/// (Euclidean) from the coordinate-wise median are dropped; at least one point is kept. Ties are
/// broken by index, so the result is deterministic. trim = 0 returns 0..N-1.
/// PRE: check_fit_points(points), check_trim(trim).
std::vector<std::size_t> trimmed_indices(PointsView points, double trim);

// === Exact minimum sphere (double precision, with its certificate)
struct MinSphere {
  double center[3] = {0, 0, 0};
  double radius = 0;                 ///< exact-algorithm radius (no inflation)
  std::vector<std::size_t> support;  ///< indices of 1–4 points on the boundary
};

/// Exact minimum enclosing sphere of points[indices] (all points if indices is null).
/// PRE: at least one point, all finite. POST: every point within radius up to round-off
/// (check with sphere_fit_check); support non-empty.
MinSphere min_sphere_exact(PointsView points, const std::vector<std::size_t>* indices = nullptr);

/// Miniball-style self-check of a MinSphere against its input (tests use it).
struct SphereFitCheck {
  double max_excess = 0;     ///< max over points of (|p − c| − r) / r, ≤ ~1e-12 if valid
  double support_error = 0;  ///< max over support points of ||p − c| − r| / r
  /// How far the centre is from the convex hull of the points on the sphere (the support plus
  /// up to 12 distinct boundary points in all, for cospherical input where the support is not
  /// unique): −min barycentric coordinate over affinely independent subsets (0 if inside).
  /// A ball enclosing the points is minimal iff its centre lies in that hull.
  double suboptimality = 0;
  double relative_error() const {
    return max_excess > support_error ? max_excess : support_error;
  }
  bool is_valid(double tol = 1e-10) const {
    return relative_error() <= tol && suboptimality <= tol;
  }
};
SphereFitCheck sphere_fit_check(PointsView points, const MinSphere& s);

// === Fitting (the library entry points)
/// Minimum enclosing sphere of `points` (N ≥ 1, finite), float result inflated so that it
/// contains every point (contains_all holds with tolerance 0). With trim > 0, the points
/// dropped by trimmed_indices(points, trim) are ignored (outlier branches); the result then
/// contains the kept points only.
/// Radius ≥ min_proxy_radius(centre). Degenerate input: one point or all duplicates → centred
/// there with radius min_proxy_radius;
/// collinear → the sphere on the extreme segment; coplanar → the smallest circle's sphere.
/// Throws std::invalid_argument: N == 0, non-finite coordinates, trim outside [0, 0.5).
Sphere fit_min_sphere(PointsView points, double trim = 0.0);

/// True if every point satisfies |p − c| ≤ r·(1 + rel_tol), evaluated in double.
bool contains_all(const Sphere& s, PointsView points, double rel_tol = 0.0);

}  // namespace canopy_ao
