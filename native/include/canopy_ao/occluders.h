// Canopy AO — large occluders: shells seen from outside as sphere occluders (docs/DESIGN.md, 'The
// method ladder';
// Hegeman 2006 Eq. 7–8, Shanmugam & Arikan 2007 Eq. 2–5).
//
// One occluder. A solid sphere whose centre is at angle θ from the receiver's normal and whose
// angular radius is σ (sin²σ = (r/d)²) blocks this fraction of the cosine-weighted AO:
//   cos²θ > sin²σ (wholly above or below the horizon):   sin²σ · max(cos θ, 0)
//   otherwise (crossing the horizon), x = sqrt(1/sin²σ − 1), y = −x cos θ / sin θ:
//     ([cos θ · acos y − x sin θ sqrt(1 − y²)] sin²σ + atan(sin θ sqrt(1 − y²) / x)) / π
// (Snyder's sphere form factor; Frostbite's illuminanceSphereOrDisk.) Hegeman's Eq. 8 ignores
// the normal and the horizon; Shanmugam–Arikan's Eq. 2 ignores the horizon.
//
// Shell opacity. A leaf shell is not opaque. With the in-shell model's τ read as a uniform
// medium of extinction τ per shell radius (so the centre sees exp(−τ) in every direction, as
// in canopy_model.h), a ray crossing the shell has transmittance exp(−τ L/R); we use the mean
// chord of a sphere, L = 4R/3 (Cauchy: 4V/S), so
//   opacity = 1 − exp(−4τ/3),   occ = opacity · sphere_occlusion(cos θ, sin²σ).
// solid = true uses opacity 1 (opaque objects, checks against ray tracing).
//
// Medium law (OccluderLaw::Medium, the default). The shell seen from outside is what the medium
// table (medium_table.h) integrates: a ball of uniform random medium, τ per radius, so the
// expected visibility is exactly medium_ao(r, cosβ, τ) (each direction transmits exp(−σ·chord),
// horizon included) — chords near the rim are short, which the single mean-chord opacity above
// ignores. Ellipsoids are mapped to the unit sphere (docs/DESIGN.md, 'The method ladder'). Its
// blocked fraction is ≤ the
// opaque unit sphere's ≤ 1/|x'|² ≤ (r_max/d)² (up to the table's < 1e-3 interpolation), so
// the cut-off below stays conservative. Measured (bench/forest.py --check, 36 real round trees,
// ground vs Embree): bias −0.133 (solid × opacity) → −0.079 (medium); most of the gain is the
// unit-frame mapping of the ellipsoids, the chord distribution adds ~0.005–0.01.
//
// Solid × opacity law (OccluderLaw::SolidOpacity, occluder_visibility; also the outside law of
// canopy_model.h's blend band): ellipsoid shells are replaced by the sphere at their centre with
// the same projected area seen from the receiver: r_eq² = r₁r₂r₃ · sqrt(Σ (u·a_k / r_k)²), u the
// unit direction to the centre (exact for spheres and for far receivers; approximate near flat
// or long shells).
//
// Many occluders: V = Π (1 − occ_i). Each occluder is ignored beyond
//   d_far = r_max / sin(acos(1 − ε/2π))          (Shanmugam–Arikan Eq. 5)
// where its blocked fraction is ≤ sin²σ ≤ (ε/π)(1 − ε/4π) < ε; a uniform grid over the
// occluders' reach bounds the cost per receiver by the local occluder density, not their count.
// ε = 0 disables the cut-off (every occluder for every receiver).
//
// AO distance D (Cycles' hard cut-off: a ray counts only what it meets within D). The
// directions from x that meet a sphere (centre at distance d, radius r) within D form a
// circular cone about the direction to its centre: the whole silhouette (sin²σ = r²/d²) when D
// reaches the tangent points (D² ≥ d² − r²); nothing when D ≤ d − r; between, the cone through
// the circle where the sphere meets the ball of radius D about x,
//   cos α = (D² + d² − r²) / (2 D d)          (law of cosines; reach_sin2 below),
// so the opaque sphere's occlusion is sphere_occlusion(cos θ, sin²α), exact. A shell (either
// law) blocks its own fraction times sphere_occlusion(α)/sphere_occlusion(σ): the share of its
// silhouette's cosine-weighted solid angle within reach (exact as D → ∞ and D ≤ d − r; the
// chord inside a partly reached shell is not shortened). Shells' reach for the spatial grid is
// min(d_far, D + r_max).
//
// Receivers inside a shell (|x'| ≤ 1 in its unit frame) skip that shell: inside is the canopy
// model's job (canopy_model.h). Zero-length normals: treated as facing away from the occluder
// (it is below the horizon, occ = 0). All results in [0, 1], 1 = open sky.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "canopy_ao/fast_math.h"
#include "canopy_ao/geometry.h"
#include "canopy_ao/medium_table.h"

namespace canopy_ao {

/// Snyder's horizon-clipped form factor of a sphere (the formula above), the one definition:
/// branch-free with fast_acos / fast_atan2_pos, so loops over it vectorise (canopy_model.cpp's
/// blend band calls it per point; sphere_occlusion is it with argument checks). c = cos θ in
/// [−1, 1], s2 = sin²σ > 0; s2 ≥ 1 gives the half-space (1 + c)/2.
inline float sphere_occlusion_law(float c, float s2) {
  const float s = std::sqrt(std::max(1.0f - c * c, 0.0f));
  const float xs = std::sqrt(std::max(1.0f / s2 - 1.0f, 0.0f));
  const float yv = clampf(-xs * c / std::max(s, 1e-20f), -1.0f, 1.0f);
  const float sy = std::sqrt(std::max(1.0f - yv * yv, 0.0f));
  const float crossing =
      clampf(((c * fast_acos(yv) - xs * s * sy) * s2 + fast_atan2_pos(s * sy, xs)) *
                 0.318309886183791f,
             0.0f, 1.0f);
  const float clear = std::max(c, 0.0f) * s2;  // wholly above (or below: 0) the horizon
  const float occ = c * c > s2 ? clear : crossing;
  return s2 >= 1.0f ? 0.5f * (1.0f + c) : occ;  // on the sphere: the half-space
}

/// sin² of the half-angle of the cone of directions that meet a sphere (squared centre
/// distance d2, squared radius r2) within distance D (see "AO distance" above): r2/d2 when D
/// reaches the tangent points, 0 when D ≤ d − r. D = +inf gives r2/d2.
inline float reach_sin2(float d2, float r2, float distance) {
  const float full = std::min(r2 / d2, 1.0f);
  if (!(distance * distance < d2 - r2)) return full;  // reaches the silhouette (or inside)
  const float d = std::sqrt(d2);
  if (distance <= d - std::sqrt(r2)) return 0.0f;
  const float ca = (distance * distance + d2 - r2) / (2.0f * distance * d);
  return std::min(std::max(1.0f - ca * ca, 0.0f), full);
}

/// Exact horizon-clipped cosine-weighted fraction of the AO hemisphere blocked by a solid
/// sphere with angular radius σ whose centre is at angle θ from the normal. In [0, 1].
/// sin2_sigma ≥ 1 means the receiver is on (or in) the sphere: the half-space behind the
/// tangent plane, (1 + cos θ)/2. sin2_sigma ≤ 0 → 0.
float sphere_occlusion(float cos_theta, float sin2_sigma);

/// Opacity of a leaf shell of optical depth τ seen from outside: 1 − exp(−4τ/3).
float shell_opacity(float tau);

/// Visibility (1 − occ) of one receiver outside one shell, no ε cut-off; `distance` the AO
/// distance (+inf: unlimited). 1 if x is inside.
float occluder_visibility(Vec3 x, Vec3 n, const Ellipsoid& shell, float opacity,
                          float distance = std::numeric_limits<float>::infinity());

/// Visibility of one receiver outside one shell under the medium law (OccluderLaw::Medium):
/// the receiver is mapped into the shell's unit frame (docs/DESIGN.md, 'The method ladder', as
/// ao_medium_ellipsoid) and
/// the shell is the uniform random medium of medium_table.h (τ per radius), so
/// V = medium_ao(|x'|, n'·x'/|x'|, τ) — exact for spheres; exactly 1 when the shell is wholly
/// below the horizon. `slice` = MediumTable::get().slice(τ). 1 if x is inside or n = 0.
float occluder_visibility_medium(Vec3 x, Vec3 n, const Ellipsoid& shell,
                                 const MediumTable::Slice& slice,
                                 float distance = std::numeric_limits<float>::infinity());

// === Options
enum class OccluderLaw {
  SolidOpacity,  ///< solid sphere × mean-chord opacity 1 − exp(−4τ/3) (Hegeman / Snyder)
  Medium,        ///< expected occlusion of a uniform medium ball (medium_table.h), unit frame
};

struct OccluderOptions {
  float tau = 1.0f;         ///< shells' optical depth (canopy_model.h meaning), ≥ 0
  float epsilon = 1e-3f;    ///< cut-off, in [0, 1); 0 = no cut-off
  bool solid = false;       ///< opaque occluders (opacity 1), τ and law ignored
  OccluderLaw law = OccluderLaw::Medium;  ///< how a (non-solid) shell occludes
  /// AO distance D (> 0; +inf = unlimited): a hard cut-off, as Cycles (see "AO distance").
  float distance = std::numeric_limits<float>::infinity();
};

/// The τ-dependent part of a shell's law: what OccluderOptions' τ, solid and law select. The
/// spatial grid does not depend on it (the reach is r_max, ε and D alone), so a field built
/// once can be evaluated under other τ (a calibration's search, one τ per tree).
struct OccluderMaterial {
  float opacity = 1.0f;       ///< SolidOpacity (solid: 1)
  bool medium = false;        ///< OccluderLaw::Medium and not solid
  MediumTable::Slice slice;   ///< the medium table at τ (medium only)
  /// The material options ask for. PRE: τ valid unless solid (std::invalid_argument). Builds
  /// the medium table on first use: call outside any parallel_for_blocks body.
  static OccluderMaterial of(const OccluderOptions& options);
};

/// A set of occluders with their spatial grid, built once, evaluated many times.
class OccluderField {
 public:
  // === Constructor
  /// PRE: each shell valid (radii > 0, orthonormal axes); options valid. Throws
  /// std::invalid_argument otherwise. An empty list is allowed (V = 1 everywhere).
  /// groups: empty, or one group ≥ 0 per shell (e.g. the tree it belongs to) for the grouped
  /// visibility below, where each group gets its own material.
  OccluderField(std::vector<Ellipsoid> shells, const OccluderOptions& options,
                std::vector<std::int32_t> groups = {});

  // === Methods
  /// positions, normals: N×3; out: N floats in [0, 1].
  void ao(PointsView positions, PointsView normals, float* out) const;
  /// One receiver.
  float visibility(Vec3 x, Vec3 n) const;
  /// One receiver, shell i with material *by_group[group(i)] (a field built with groups; the
  /// caller's array covers every group), the shells of group `skip` left out (−1: none).
  float visibility(Vec3 x, Vec3 n, const OccluderMaterial* const* by_group,
                   std::int32_t skip) const;
  /// One receiver, every shell with the field's own material, those of group `skip` left out
  /// (−1: none).
  float visibility(Vec3 x, Vec3 n, std::int32_t skip) const;
  /// The group of shell i (0 for a field built without groups).
  std::int32_t group(std::size_t i) const { return groups_.empty() ? 0 : groups_[i]; }

  // === Introspection (tests, reports)
  std::size_t size() const { return shells_.size(); }
  /// Largest number of candidate occluders in one grid cell (the per-receiver cost bound).
  std::size_t max_candidates() const { return max_candidates_; }
  /// Reach of occluder i: min(d_far, D + r_max) (inf when ε = 0 and D = inf).
  float cutoff(std::size_t i) const { return far_[i]; }

 private:
  std::vector<Ellipsoid> shells_;
  std::vector<float> far_;   // d_far per occluder
  std::vector<float> rmax_;  // largest semi-axis per occluder (bounding sphere)
  template <class MaterialOf>
  float visit(Vec3 x, Vec3 n, MaterialOf&& material_of) const;

  std::vector<std::int32_t> groups_;  // per shell (empty: ungrouped)
  float distance_ = std::numeric_limits<float>::infinity();
  OccluderMaterial material_;  // the options' material (ungrouped visibility)
  bool unbounded_ = false;  // ε = 0: one list holds every occluder
  Vec3 lo_;                 // grid origin
  float inv_cell_ = 1.0f;
  int dims_[3] = {1, 1, 1};
  std::vector<std::uint32_t> cell_start_;  // CSR: cell c holds items_[cell_start_[c] .. [c+1])
  std::vector<std::uint32_t> items_;
  std::size_t max_candidates_ = 0;
};

/// One-off: builds an OccluderField and evaluates it.
void ao_occluders(PointsView positions, PointsView normals, const std::vector<Ellipsoid>& shells,
                  const OccluderOptions& options, float* out);

}  // namespace canopy_ao
