// Canopy AO — cheap per-vertex occlusion features and the linear model that maps them to AO:
// the ray-free "regression" rung. No rays at bake time; the cost per receiver does not depend on
// the leaf count.
//
// Why. The leaf-density grid (density_grid.h) follows where the leaves really are but misses
// what is below a voxel: a leaf shaded by its neighbour or by its own branch. The traced
// calibration sample (≤ 1024 points) measures exactly that per scene, so a small regression of
// the sample against features that describe a receiver's surroundings carries it over to every
// vertex (docs/DESIGN.md, "The method ladder"; Loos & Sloan 2010 for volumetric line integrals).
//
// Precomputation (once per grid, O(voxels × K), independent of the receivers): for K fixed
// directions d_k (a golden-angle spiral over the whole sphere) the optical depth from every voxel
// centre out of the grid along d_k,
//     τ_k(c) = ∫_0^∞ σ(c + t d_k) dt,
// by one semi-Lagrangian sweep per direction: slices along the dominant axis of d_k from the exit
// side, each voxel taking its upstream neighbour one slice away, bilinearly interpolated, plus
// the trapezoid σ·step (the recurrence of deep shadow maps, Lokovic & Veach 2000).
//
// Features per receiver (x, n), all scale-free (lengths divided by the voxel size or the tree's
// size), in this order (names from feature_name()):
//   0-2  grid AO at σ scales ½, 1, 2: cosine-weighted mean over the d_k with n·d_k > 0 of
//        exp(−s τ_k(x)) (τ trilinear at x; receivers outside the grid read τ where d_k enters it)
//   3    sky view: mean over upward d_k weighted by d_k·z of exp(−τ_k(x)), normal-free
//   4    log(1 + cosine-weighted mean of τ_k over the hemisphere)   (how deep in the canopy)
//   5    log(1 + σ h) at x                                          (local leaf density)
//   6    n·z;  7  n·radial (horizontal direction from the tree's axis)
//   8    height in the tree's vertical range, 0..1;  9  horizontal distance from the axis / radius
//   10   n·(x − m)/|x − m|, m the frame's mid-point (centre xy, mid height): facing out or in
//   11   |x − m| / (half the frame's diagonal)
//   12   the normal's grid AO minus its opposite's (feature 1 − the same for −n): the open side
// Up is +Z (Blender's world up). Measured on Sapling trees (bench/real_assets.py): the shape
// features 6-9 carry most of what the grid misses; a distance-to-branch field, a coarser level
// and a lookup one voxel out along n each changed the MAE by < 0.001 and were left out.
//
// The model: z = (f − mean) / scale per feature, φ(z) = [1, z_1..z_F, z_1²..z_F², z_1 z_2 ..
// z_1 z_F] (squares and the products with the grid AO; for these 13 features also the pairwise
// products of the shape features 6-11: how a leaf faces depends on where it is in the crown),
// AO = clamp(w·φ(z), 0, 1). The weights come from a ridge fit on the traced sample
// (addon/canopy_ao/core/regression.py).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "canopy_ao/density_grid.h"
#include "canopy_ao/geometry.h"

namespace canopy_ao {

struct OcclusionFeatureOptions {
  int directions = 24;  ///< K fixed directions over the sphere (6..256)
};

/// A tree's frame for the shape features: vertical axis through `center`, horizontal `radius`
/// (> 0), vertical range [z_min, z_max].
struct TreeFrame {
  Vec3 center;
  float radius = 1;
  float z_min = 0, z_max = 1;
};

class OcclusionFeatures {
 public:
  static constexpr int kCount = 13;

  // === Constructor
  /// occluders: the grid of everything that casts occlusion (leaves, branches, grass), read
  /// during construction only. Throws std::invalid_argument on bad options.
  explicit OcclusionFeatures(const DensityGrid& occluders,
                             const OcclusionFeatureOptions& options = {});

  // === Methods
  /// Features of N receivers into out (N × kCount floats, row-major). Parallel, deterministic.
  /// A zero normal gives the normal-dependent features of an open receiver (AO features 1).
  /// Throws std::invalid_argument on non-finite input or a bad frame.
  void compute(PointsView positions, PointsView normals, const TreeFrame& frame,
               float* out) const;

  int directions() const { return static_cast<int>(dirs_.size()); }
  static const char* feature_name(int f);

 private:
  struct Field {  // per-direction optical depth on one grid level's voxel-centre lattice
    Vec3 origin;  // centre of voxel (0, 0, 0)
    float h = 1;
    int n[3] = {0, 0, 0};
    std::vector<float> sigma;
    std::unique_ptr<float[]> tau;  // [direction][voxel], K × (n0 n1 n2) values
  };
  static Field sweep(const DensityGrid& g, int level, const std::vector<Vec3>& dirs);
  static float lerp3(const Field& f, const std::vector<float>& v, Vec3 p);
  // compute()'s per-block work (occlusion_features.cpp), one body built twice: the baseline's
  // and AVX2's (no FMA: the same bits).
  struct FeatureContext;
  static void features_block(const FeatureContext& c, std::size_t b, std::size_t e,
                             float* taus, float* tr, float* sq, float* tile);
  static void features_portable(const FeatureContext& c, std::size_t b, std::size_t e,
                                float* taus, float* tr, float* sq, float* tile);
  struct avx2 {
    static void features(const FeatureContext& c, std::size_t b, std::size_t e, float* taus,
                         float* tr, float* sq, float* tile);
  };
  // τ_k for every direction at p into tau (K values): one trilinear stencil for all directions
  // inside the grid; outside, each direction reads where it enters the grid.
  void taus_at(Vec3 p, float* tau) const;
  // The receivers' indices in an order that walks the grid bucket by bucket (cache reuse).
  // bucket: null, or each receiver's bucket in that order.
  std::vector<std::uint32_t> coherent_order(PointsView positions,
                                            std::vector<std::uint32_t>* bucket = nullptr) const;

  std::vector<Vec3> dirs_;
  Field fine_;
};

/// Whether OcclusionFeatures::compute runs its AVX2 copy (chosen by the CPU on first use);
/// both copies give the same bits. set_...(true) throws std::invalid_argument on a CPU without
/// AVX2. For tests and benchmarks.
bool occlusion_features_kernel_avx2();
void set_occlusion_features_kernel_avx2(bool on);

// === The linear model
/// Number of expanded terms for F raw features: 1 + F + F + (F − 1), plus the 15 pairwise
/// products of the shape features 6-11 when F = OcclusionFeatures::kCount.
int expanded_size(int features);

/// φ(z) of N rows of F raw features into out (N × expanded_size(F)). mean, scale: F values
/// (scale > 0). Throws std::invalid_argument on a non-positive or non-finite scale.
void expand_features(const float* features, std::size_t n, int f, const float* mean,
                     const float* scale, float* out);

/// AO = clamp(w·φ(z), 0, 1) for N rows into out (N floats); weights: expanded_size(F) values.
void predict_features(const float* features, std::size_t n, int f, const float* mean,
                      const float* scale, const float* weights, float* out);

/// Number of terms of a model over F features whose first F_native expand as expand_features
/// does for F_native and whose F − F_native extra ones (the leaf-piece columns) add
/// [z_e, z_e², z_grid·z_e] each group in turn: expanded_size(F_native) + 3 (F − F_native).
int model_size(int features, int native_features);

/// AO = clamp(w·φ(z), 0, 1) of that model for N rows of F features into out (N floats;
/// 1 where the sum is not finite); weights: model_size(F, F_native) values. lo, hi: null, or F
/// bounds each feature is held to first (a live frame's features, the calibration sample's
/// range). Throws std::invalid_argument on a bad F_native or scale.
void predict_model(const float* features, std::size_t n, int f, int f_native, const float* mean,
                   const float* scale, const float* weights, const float* lo, const float* hi,
                   float* out);

}  // namespace canopy_ao
