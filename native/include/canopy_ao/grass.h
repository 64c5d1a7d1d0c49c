// Canopy AO — grass (Hegeman et al. 2006, Eq. 9; docs/DESIGN.md, 'The method ladder').
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
#pragma once

#include "canopy_ao/geometry.h"

namespace canopy_ao {

struct GrassOptions {
  float ground_height = 0.0f;  ///< ground level along `up` (world units), finite
  float blade_height = 1.0f;   ///< h > 0 (world units)
  Vec3 up = {0, 0, 1};         ///< non-zero, normalised internally
  float floor = 0.05f;         ///< in [0, 1]
};

/// One receiver.
float grass_visibility(Vec3 x, Vec3 n, const GrassOptions& options);

/// positions, normals: N×3; out: N floats. Bad options throw std::invalid_argument.
void ao_grass(PointsView positions, PointsView normals, const GrassOptions& options, float* out);

}  // namespace canopy_ao
