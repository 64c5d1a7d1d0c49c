// Canopy AO — a grass field as an occluder of the ground under it (docs/DESIGN.md, 'How each
// role is lit', GROUND under grass).
//
// Hegeman's Eq. 9 (grass.h) lights the blades and gives 0 at their roots for any density; the
// ground between them sees the sky through the blade layer. core/grass_layer.py measures, once
// per field, its leaf area index L and the blades' projection function from their triangles
// and integrates the layer's visibility V of an upward-facing ground point (Ross's G-function,
// Monsi–Saeki's Beer law); it also keeps the field's footprint: the xy cells of size h its
// blades stand in. This file is the per-point part:
//  - a point further than one blade height from the field's ground level (|z − ground| >
//    blade) sees 1;
//  - otherwise, with m = max(1, ⌈blade / h⌉) and (i, j) = ⌊(xy − origin) / h⌋ its cell, it
//    sees 1 − f (1 − V), f the share of the disc of cells (di² + dj² ≤ m²) around its cell
//    that the footprint holds: V inside the field, about half-way at its edge, 1 away.
// Arithmetic in double as the Python formula it replaced (tests/python/lighting_reference.py
// keeps it as the reference), so results are bit-equal to it. The disc is counted row by row
// (two binary searches over the sorted cells per row), so a point costs O(m log K), not O(m²).
#pragma once

#include <cstdint>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

struct GrassCoverData {
  double ground = 0.0;      ///< ground level (z of the blade roots), finite
  double blade = 1.0;       ///< blade height, finite, > 0
  double visibility = 1.0;  ///< V under the layer, in [0, 1]
  double cell = 1.0;        ///< footprint cell size h, finite, > 0
  double origin_x = 0.0;    ///< the cells' origin (cell (0, 0) starts there), finite
  double origin_y = 0.0;
  std::int64_t width = 1;   ///< cells per row (key = i · width + j, 0 ≤ j < width), ≥ 1
  std::vector<std::int64_t> keys;  ///< the footprint's cells, strictly increasing, in [0, 2^52)
};

class GrassCover {
 public:
  // === Constructor
  /// Largest m = ⌈blade / h⌉ accepted (the disc's radius in cells).
  static constexpr std::int64_t kMaxDiscCells = 1 << 20;
  /// PRE: the data as documented above (width < 2^52), m ≤ kMaxDiscCells. Throws
  /// std::invalid_argument.
  explicit GrassCover(GrassCoverData data);

  // === Methods
  /// The ground's visibility at one point (in [V, 1]).
  float visibility(Vec3 x) const;
  /// out[i] = visibility(positions[i]), N points (parallel).
  void ground_visibility(PointsView positions, float* out) const;

  // === Introspection
  const GrassCoverData& data() const { return d_; }

 private:
  GrassCoverData d_;
  std::int64_t m_ = 1;               // the disc's radius in cells
  std::vector<std::int64_t> half_;   // per row di + m: largest |dj| with di² + dj² ≤ m²
  double total_ = 1.0;               // cells in the disc
  std::int64_t row_lo_ = 0, row_hi_ = 0;  // the footprint's first and last row
};

}  // namespace canopy_ao
