// Canopy AO — exact expected AO inside (and around) a shell filled with a uniform random medium
// of leaves, tabulated so it costs one table lookup per vertex (docs/DESIGN.md, 'The method
// ladder').
//
// Model. A sphere (centre C, radius R) is filled with randomly oriented small leaves of area
// density ρ (leaf area per volume). A ray of length l through it is transmitted with probability
// exp(−σ l), σ = ρ/2 (the mean projected area of a randomly oriented flat leaf is half its area).
// The expected cosine-weighted AO of a receiver at x with unit normal n is
//
//     AO(x, n) = (1/π) ∫_{ω·n>0} exp(−σ L(x, ω)) (ω·n) dω          (docs/DESIGN.md, 'What AO
// means here', D = ∞)
//
// with L the length of the ray's segment inside the sphere (for x outside the sphere: the chord
// it cuts, 0 if it misses). By symmetry AO depends only on
//   r    = |x − C| / R                         (0 = centre, 1 = surface, > 1 outside),
//   cosβ = n · (x − C)/|x − C|                 (+1 = normal facing away from the centre),
//   τ    = σ R                                 (optical depth centre → surface).
// τ is exactly the DESIGN's scale-free τ: at the centre every chord is R, so AO = exp(−τ) for any
// normal. Hegeman's Eq. 4–6 (canopy_model) approximates the same quantity; this is the expectation.
// No AO distance: rays run to the shell boundary (D = ∞, or D ≥ 2R); a finite D would need a
// fourth table axis (D/R) — use the density grid, which honours D, for that.
//
// Table. The azimuth around the radial axis is integrated in closed form, leaving a 1D integral
// over the angle to the radial axis (512-point midpoint rule, |ΔAO| ≤ 1.1e-4 against 8192
// points; see medium_ao_quadrature). The table stores the *effective chord* L_eff = −ln(AO)/τ
// (its τ → 0 limit at τ = 0), which varies slowly in all three axes, so AO = exp(−τ · L_eff) is exactly 1 at τ = 0, exactly exp(−τ) at
// the centre, and interpolation stays accurate (|ΔAO| < 1e-3 at off-grid points, worst seen
// 7e-4; tests/cpp/test_medium_table.cpp). Axes:
//   r     : 64 nodes on [0, 1], r = 1 − (1 − u)² (dense near the surface, where AO changes
//           fast at high τ), then 32 nodes with 1 − 1/r ∝ v² (dense just outside) up to r = 8;
//   cosβ  : 95 nodes, cosβ = ±(1 − (1 − |q|)²), q uniform (dense where n is near-radial);
//   τ     : 48 nodes uniform in log(1 + τ) on [0, 32]; between τ nodes g = τ·L_eff = −ln AO is
//           interpolated linearly in τ, so AO is monotone in τ and exact at τ = 0 and r = 0.
// Beyond r = 8 the occlusion falls off as (8/r)² (a far sphere's solid angle); beyond τ = 32
// L_eff is held at its τ = 32 value (AO there is < e^-32·L, far below anything visible inside
// and a mild underestimate of occlusion outside). The table (96×95×48 floats, 1.75 MB) is built
// once, lazily and thread-safely, in ~0.15 s of CPU, bit-identical whatever the thread count.
#pragma once

#include <cstddef>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

/// Expected AO of a uniform random medium in the unit sphere, by direct 1D quadrature (no table).
/// r ≥ 0 (|x − C|/R), cos_beta ∈ [−1, 1], tau ≥ 0 (σR). `samples` = midpoint-rule nodes over
/// the polar angle (the azimuth is integrated exactly). Used to build the table and by tests.
double medium_ao_quadrature(double r, double cos_beta, double tau, int samples = 2048);

/// The tabulated expectation. Obtain it with MediumTable::get(); call get() outside any
/// parallel_for_blocks body (its first call builds the table with parallel_for_blocks).
class MediumTable {
 public:
  static constexpr int kRadiusInside = 64;   ///< nodes on r ∈ [0, 1]
  static constexpr int kRadiusOutside = 32;  ///< nodes on r ∈ (1, kMaxRadius]
  static constexpr int kRadius = kRadiusInside + kRadiusOutside;
  static constexpr int kCos = 95;   ///< nodes on cosβ ∈ [−1, 1], dense near ±1
  static constexpr int kTau = 48;   ///< nodes on τ ∈ [0, kMaxTau], log-spaced
  static constexpr double kMaxRadius = 8.0;
  static constexpr double kMaxTau = 32.0;

  // === Constructor
  /// The process-wide table, built on first use (thread-safe).
  static const MediumTable& get();

  // === Methods
  /// Expected AO at r = |x − C|/R, cosβ, τ = σR (trilinear lookup). Value in [0, 1].
  float ao(float r, float cos_beta, float tau) const;

  /// A (r, cosβ) plane of the table at one τ: a bilinear lookup per point. Cheap to make
  /// (6k values); use one per call when τ is shared by all points.
  class Slice {
   public:
    float ao(float r, float cos_beta) const;
    float tau() const { return tau_; }

   private:
    friend class MediumTable;
    float tau_ = 0;
    std::vector<float> leff_;  // [kRadius][kCos]
  };
  Slice slice(float tau) const;

  /// Effective chord stored at node (i_r, i_cos, i_tau); for tests.
  float node(int ir, int ic, int it) const { return leff_[(ir * kCos + ic) * kTau + it]; }
  static double radius_of_node(int ir);
  static double cos_of_node(int ic);
  static double tau_of_node(int it);

 private:
  MediumTable();
  std::vector<float> leff_;  // [kRadius][kCos][kTau]
};

// === Per-point evaluation (parallel, deterministic). out has N floats, values in [0, 1].
/// Sphere: positions/normals N×3. tau = σR ≥ 0. A zero normal gives 1 (no hemisphere, as the ray-traced reference).
/// Throws std::invalid_argument on a non-finite or non-positive radius or a bad tau.
void ao_medium_sphere(PointsView positions, PointsView normals, const Sphere& sphere, float tau,
                      float* out);

/// Ellipsoid: mapped to the unit sphere as docs/DESIGN.md, 'The method ladder' (x' = diag(1/r)
/// Qᵀ(x − C), normals by the
/// inverse transpose) and looked up with the same τ. Approximation: exact for a medium whose
/// optical depth from the centre to the surface is τ along every axis (σ scaled by 1/radius per
/// direction) *and* whose cosine lobe is taken in the mapped frame; for a real uniform medium in
/// an elongated ellipsoid it under-weights the long axis. Exact for spheres.
void ao_medium_ellipsoid(PointsView positions, PointsView normals, const Ellipsoid& ellipsoid,
                         float tau, float* out);

enum class MediumCombine {
  Product,  ///< product of every shell's AO (inside: the medium; outside: a soft occluder)
  Nearest,  ///< the shell with the closest centre only (Hegeman §5; seams between shells)
};

/// Several shells. `taus` has one τ per shell or a single τ for all. Product treats the shells'
/// transmittances as independent (exact per ray for overlapping media, approximate on average).
void ao_medium_shells(PointsView positions, PointsView normals,
                      const std::vector<Ellipsoid>& shells, const std::vector<float>& taus,
                      MediumCombine combine, float* out);
/// The same with the table's slices given (one for every shell, or one per shell; each
/// MediumTable::get().slice(τ)), for a caller that keeps them across calls (scene_plan.h).
void ao_medium_shells_sliced(PointsView positions, PointsView normals,
                             const std::vector<Ellipsoid>& shells,
                             const std::vector<const MediumTable::Slice*>& slices,
                             MediumCombine combine, float* out);

}  // namespace canopy_ao
