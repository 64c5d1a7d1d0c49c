// Canopy AO — leaf-density grid (docs/DESIGN.md, 'The method ladder'): the leaf (and branch) area
// voxelised into an
// extinction field, AO from a few cosine-weighted line integrals through it. Between the fitted
// proxies (one uniform medium per shell) and ray tracing (every leaf): it models how the leaves
// are really spread, at a cost per receiver that does not depend on the leaf count.
//
// Extinction. A randomly oriented flat leaf of area a has mean projected area a/2, so leaf area
// density ρ gives σ = ρ/2 (Ross G-function 0.5). Per voxel: σ = (area of triangles in it) /
// (2 · voxel volume) — no hand-tuned factor. Closed surfaces (branch tubes) are counted the same
// way, which is 2× their Cauchy mean projection (S/4): branches come out twice as dense as their
// silhouette — acceptable for solid wood; `sigma_scale` scales everything at evaluation time.
// Area is spread by subdividing each triangle into m² equal sub-triangles (m from its longest
// edge, ≥ 2 per voxel, capped at 32) and depositing each one's area at its centroid, so big
// triangles (a ground plane) land in every voxel they cross and total area is conserved exactly.
//
// AO (docs/DESIGN.md, 'What AO means here'): AO(x, n) = mean over K cosine-weighted directions ω
// of exp(−∫_0^D σ(x + tω) dt)
// — cosine-weighted directions make the cosine weighting a plain average. The K directions are
// a fixed golden-angle spiral on the unit disc lifted to the hemisphere (Malley), rotated about n
// by a per-point angle from a hash of (point index, seed): deterministic, decorrelated noise.
// Each line integral (Loos–Sloan's line samples, with a growing footprint like cone tracing):
//   1. [0, self_skip·h): the receiver's own voxel holds its own leaf, which cannot occlude it
//      (the ray leaves the leaf's plane at once). This stretch uses the mip level-2 density
//      (a 4h cube's mean), which dilutes the own leaf 64× yet keeps a uniform medium unbiased
//      (used only where the finest level is non-zero, so a receiver just outside dense geometry
//      stays open). Leaves larger than a voxel still shade their own vertices on grazing rays.
//   2. up to kExactVoxels·h: exact per-voxel integration on the finest level (3D-DDA,
//      Amanatides–Woo 1987): Σ σ_voxel · (length of the ray inside the voxel).
//   3. beyond: steps of one voxel of mip level l, l = ⌊log2(cone footprint / h)⌋ with the
//      footprint 2·t·tan(cone), tan(cone) = sqrt(2/K) (the solid angle 2π/K each direction
//      stands for); σ sampled trilinearly at the step's midpoint. The number of steps grows
//      only logarithmically with distance.
//   The integral stops at the AO distance D (Cycles' hard cut-off), at the grid's box, or once
//   the optical depth passes 20 (transmittance < 2e-9).
// Mip levels hold the mean σ of their 2×2×2 children (missing children count as empty), so the
// optical mass is conserved at every level.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

struct DensityGridOptions {
  /// Voxels along the box's longest side (1..1024). The others get as many cubic voxels as fit;
  /// at most 2^26 voxels in all (a cube up to 406³), else std::invalid_argument.
  int resolution = 48;
};

struct DensityAOOptions {
  int directions = 32;                 ///< cosine-weighted directions per receiver (1..4096)
  float distance = INFINITY;           ///< AO distance D (world units, > 0); rays stop there
  std::uint32_t seed = 0;              ///< rotates every point's direction set differently
  float sigma_scale = 1.0f;            ///< multiplies σ (≥ 0): calibration hook, 1 = physical
  float self_skip = 1.0f;              ///< voxels at the start of each ray on the diluted level
  float start = 0.0f;                  ///< integrate from here on (world units; near/far split)
};

class DensityGrid {
 public:
  static constexpr int kExactVoxels = 4;  ///< exact DDA out to this many finest voxels
  /// Smallest voxel edge: a mesh whose extent / resolution is below it is refused (1/h and h³
  /// would leave float's normal range).
  static constexpr float kMinVoxel = 1e-30f;

  // === Constructor
  /// vertices: V×3 world positions; triangles: M×3 indices into vertices (0-based, two-sided).
  /// Throws std::invalid_argument on non-finite vertices, indices outside [0, V), a bad
  /// resolution or a voxel edge below kMinVoxel. An empty mesh (or only zero-area triangles) gives an empty grid: AO = 1.
  DensityGrid(PointsView vertices, const std::int32_t* triangles, std::size_t triangle_count,
              const DensityGridOptions& options = {});

  // === Methods
  /// AO for N receivers (positions, normals N×3) into out (N floats in [0, 1], 1 = open sky).
  /// Parallel over points (parallel_for_blocks), independent of the thread count. A zero normal
  /// gives 1 (no hemisphere; as the ray-traced reference). Throws std::invalid_argument on
  /// non-finite input or bad options.
  void ao(PointsView positions, PointsView normals, const DensityAOOptions& options,
          float* out) const;
  /// Same, and when `bent` is not null (3N floats) each receiver's bent-normal estimate
  /// (docs/DESIGN.md, 'Bent normals'): the transmittance-weighted mean of its directions,
  ///     B = normalize(Σ_k exp(−τ_k) ω_k),
  /// the grid's stand-in for the ray tracer's mean unoccluded direction (raytrace.h, "Bent
  /// normals"), with the same fallbacks: all transmittances 0 → the unit normal; zero normal →
  /// (0, 0, 0).
  void ao(PointsView positions, PointsView normals, const DensityAOOptions& options,
          float* out, float* bent) const;

  /// ∫ σ dt along origin + t·dir (dir any non-zero length, normalised safely) for
  /// t ∈ [0, t_max], with the schedule above. Every loop is bounded by the grid's size, whatever
  /// the magnitudes of origin and dir (a far receiver marches from where it enters the box);
  /// (self_skip in voxels, cone_tan the footprint half-angle's tangent). For tests/tools.
  float optical_depth(Vec3 origin, Vec3 dir, float t_max, float self_skip,
                      float cone_tan) const;

  // === Properties
  int nx() const { return dims_[0][0]; }
  int ny() const { return dims_[0][1]; }
  int nz() const { return dims_[0][2]; }
  float voxel_size() const { return h_; }
  Vec3 origin() const { return origin_; }  ///< corner of voxel (0, 0, 0)
  double total_area() const { return total_area_; }
  int levels() const { return static_cast<int>(sigma_.size()); }
  bool empty() const { return total_area_ <= 0; }
  /// σ of finest voxel (i, j, k) (per world unit); layout x fastest.
  float sigma(int i, int j, int k) const { return sigma_[0][index(0, i, j, k)]; }
  const std::vector<float>& sigma_level(int level) const { return sigma_[level]; }

 private:
  std::size_t index(int level, int i, int j, int k) const {
    const int* d = dims_[level].data();
    return (static_cast<std::size_t>(k) * d[1] + j) * d[0] + i;
  }
  float sample(int level, Vec3 p) const;  // trilinear, zero outside the grid
  float dda(Vec3 o, Vec3 d, float t0, float t1) const;
  bool clip(Vec3 o, Vec3 d, float* t0, float* t1) const;  // ray ∩ grid box
  float march(Vec3 o, Vec3 d, float t_min, float t_max, float skip_len, float cone_tan,
              float limit) const;

  Vec3 origin_;
  float h_ = 1;
  double total_area_ = 0;
  std::vector<std::array<int, 3>> dims_;
  std::vector<std::vector<float>> sigma_;  // [level][voxel], level 0 = finest
};

class RayTracer;
struct RayTraceOptions;
struct OwnPrimitives;

/// "Near exact, far statistical": Embree rays (raytrace.h) out to `near` (scene units, > 0),
/// the density grid from `near` to rt.distance, multiplied:
///     AO ≈ AO_traced(0, near) · AO_grid(near, D)
/// (the product of the two averages stands for the average of the products: exact when near
/// and far occlusion are independent, which a random canopy roughly is). Contact shadows and
/// the receiver's own leaf come from real geometry; the canopy's bulk costs a grid march.
/// far.distance and far.start are overridden. Shapes and errors as RayTracer::ao/DensityGrid::ao.
/// own: the receivers' own primitives, as RayTracer::ao takes them (a vertex receiver starts at
/// Cycles' bake point and casts its samples at every face corner, as the exact rung does).
void ao_near_far(const RayTracer& tracer, const DensityGrid& grid, PointsView positions,
                 PointsView normals, float near, const OwnPrimitives& own,
                 const RayTraceOptions& rt, const DensityAOOptions& far, float* out);
/// As above with no own primitives: every receiver a free point (the normal-offset start).
void ao_near_far(const RayTracer& tracer, const DensityGrid& grid, PointsView positions,
                 PointsView normals, float near, const RayTraceOptions& rt,
                 const DensityAOOptions& far, float* out);

}  // namespace canopy_ao
