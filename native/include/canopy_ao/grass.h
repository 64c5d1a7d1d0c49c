// Canopy AO — grass blades (Hegeman et al. 2006, Eq. 9, or the field's measured blade layer;
// docs/DESIGN.md, 'How each role is lit').
//
//   V = (Pz / 2h) (1 + cos θ),  clamped to [floor, 1]
// Pz = dot(x, up) − ground_height (height above the ground along `up`), h the blade height,
// θ the angle between the normal and up. Details:
//  - Pz is clamped to [0, h]: above the blades a receiver sees the sky like a tilted plane,
//    (1 + cos θ)/2 — the law's own value at the blade tip — and below the ground Pz = 0.
//  - The law gives 0 at the roots; `floor` keeps the darkest value at an artist-chosen level.
//    Ground points under the grass use the same law: Pz = 0 → V = floor.
//  - Zero-length normals are treated as horizontal (cos θ = 0): a blade's typical normal.
// Results in [floor, 1] ⊂ [0, 1], 1 = open sky.
//
// Eq. 9 does not know how dense the grass is (a sparse field and a dense one get the same AO).
// Given a blade layer (GrassOptions::layer), V is read from it instead: the field's own
// visibility V(s, c) at relative height s = Pz / h and cos θ = c, integrated once per field
// from its blades (core/grass_layer.py: leaf area index, projection function and how the blade
// area is spread over the height, the AO distance), read bilinearly and clamped as above.
#pragma once

#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

struct GrassOptions {
  float ground_height = 0.0f;  ///< ground level along `up` (world units), finite
  float blade_height = 1.0f;   ///< h > 0 (world units)
  Vec3 up = {0, 0, 1};         ///< non-zero, normalised internally
  float floor = 0.05f;         ///< in [0, 1]
  /// The blade layer, or empty (Eq. 9): layer_rows × layer_cols values in [0, 1], row-major,
  /// row i at s = i / (rows − 1), column j at cos θ = −1 + 2 j / (cols − 1); rows, cols ≥ 2.
  std::vector<float> layer;
  int layer_rows = 0;
  int layer_cols = 0;
};

/// One receiver.
float grass_visibility(Vec3 x, Vec3 n, const GrassOptions& options);

/// positions, normals: N×3; out: N floats. Bad options throw std::invalid_argument.
void ao_grass(PointsView positions, PointsView normals, const GrassOptions& options, float* out);

}  // namespace canopy_ao
