// Canopy AO — a forest's instanced trees as occluders (docs/DESIGN.md, 'How each role is lit',
// instanced trees).
//
// A forest is a few prototypes, each placed by many instance matrices; core/forest.py moves
// every prototype's shells and solid trunks to world space exactly (an ellipsoid's affine image
// is an ellipsoid). Here they become one OccluderField per prototype's crowns, with that
// prototype's fixed τ (the medium law of occluders.h), and one solid field for every trunk:
// V = Π over the fields, each itself Π (1 − occᵢ) over the occluders within its cut-off ε
// (Shanmugam–Arikan Eq. 5), so a receiver's cost is bounded by the occluders within reach of
// it, not by the instance count. Built once when the forest is attached; the scene plan
// (scene_plan.h) multiplies it into every receiver it lights, and the other rungs call ao().
#pragma once

#include <cstddef>
#include <limits>
#include <vector>

#include "canopy_ao/geometry.h"
#include "canopy_ao/occluders.h"

namespace canopy_ao {

/// One prototype's crown shells at every instance (world space) and their optical depth.
struct ForestCrowns {
  std::vector<Ellipsoid> shells;
  float tau = 1.0f;
};

class ForestOccluders {
 public:
  // === Constructor
  /// PRE: shells valid, each τ valid, ε in [0, 1), distance > 0 (+inf: unlimited). Throws
  /// std::invalid_argument otherwise. Prototypes without shells add no field.
  ForestOccluders(std::vector<ForestCrowns> crowns, std::vector<Ellipsoid> solids,
                  float epsilon = 1e-3f,
                  float distance = std::numeric_limits<float>::infinity());

  // === Methods
  /// One receiver's visibility under every instance: the fields' product, in field order.
  float visibility(Vec3 x, Vec3 n) const;
  /// positions, normals: N×3; out: N floats in [0, 1] (parallel).
  void ao(PointsView positions, PointsView normals, float* out) const;

  // === Introspection
  std::size_t shells() const { return shells_; }  ///< crown shells, every prototype
  std::size_t solids() const { return solids_; }  ///< solid trunks
  /// Largest number of occluders one receiver tests (summed over the fields).
  std::size_t max_candidates() const;

 private:
  std::vector<OccluderField> fields_;
  std::size_t shells_ = 0, solids_ = 0;
};

}  // namespace canopy_ao
