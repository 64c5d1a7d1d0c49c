#include "canopy_ao/forest.h"

#include <utility>

#include "canopy_ao/model_checks.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

ForestOccluders::ForestOccluders(std::vector<ForestCrowns> crowns, std::vector<Ellipsoid> solids,
                                 float epsilon, float distance) {
  OccluderOptions o;
  o.epsilon = epsilon;
  o.distance = distance;
  for (ForestCrowns& c : crowns) {
    check_tau(c.tau);
    if (c.shells.empty()) continue;
    o.tau = c.tau;
    shells_ += c.shells.size();
    fields_.emplace_back(std::move(c.shells), o);
  }
  // Checked even when empty: the options must be valid either way.
  OccluderOptions solid = o;
  solid.tau = 1.0f;
  solid.solid = true;
  solids_ = solids.size();
  OccluderField trunks(std::move(solids), solid);
  if (solids_ > 0) fields_.push_back(std::move(trunks));
}

float ForestOccluders::visibility(Vec3 x, Vec3 n) const {
  float v = 1.0f;
  for (const OccluderField& f : fields_) v *= f.visibility(x, n);
  return v;
}

void ForestOccluders::ao(PointsView positions, PointsView normals, float* out) const {
  check_receivers(positions, normals);
  parallel_for_blocks(positions.size, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) out[i] = visibility(positions[i], normals[i]);
  });
}

std::size_t ForestOccluders::max_candidates() const {
  std::size_t m = 0;
  for (const OccluderField& f : fields_) m += f.max_candidates();
  return m;
}

}  // namespace canopy_ao
