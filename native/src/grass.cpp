// Hot loops must vectorise: see fast_math.h for why this pragma is here.
#pragma GCC optimize("no-trapping-math")

#include "canopy_ao/grass.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "canopy_ao/model_checks.h"
#include "canopy_ao/fast_math.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {
void check_grass(const GrassOptions& o) {
  if (!std::isfinite(o.ground_height)) throw std::invalid_argument("ground_height is not finite");
  if (!std::isfinite(o.blade_height) || !(o.blade_height > 0)) {
    throw std::invalid_argument("blade_height must be finite and > 0, got " +
                                std::to_string(o.blade_height));
  }
  if (!is_finite(o.up) || !(dot(o.up, o.up) > 0)) {
    throw std::invalid_argument("up must be a finite non-zero vector");
  }
  if (!std::isfinite(o.floor) || o.floor < 0 || o.floor > 1) {
    throw std::invalid_argument("floor must be in [0, 1], got " + std::to_string(o.floor));
  }
}

// Hegeman Eq. 9, with Pz clamped to [0, h] and the result to [floor, 1] (grass.h).
inline float grass_law(float px, float py, float pz, float nx, float ny, float nz, Vec3 up,
                       float ground, float inv_2h, float h, float floor) {
  const float height = clampf(px * up.x + py * up.y + pz * up.z - ground, 0.0f, h);
  const float nn = nx * nx + ny * ny + nz * nz;
  // Zero normal → cos θ = 0 (horizontal): the dot product is 0 already, only avoid 0/0.
  const float cos_t = (nx * up.x + ny * up.y + nz * up.z) / std::sqrt(std::max(nn, 1e-30f));
  return clampf(height * inv_2h * (1.0f + cos_t), floor, 1.0f);
}
}  // namespace

float grass_visibility(Vec3 x, Vec3 n, const GrassOptions& o) {
  check_grass(o);
  const Vec3 up = normalize(o.up);
  return grass_law(x.x, x.y, x.z, n.x, n.y, n.z, up, o.ground_height, 0.5f / o.blade_height,
                   o.blade_height, o.floor);
}

void ao_grass(PointsView positions, PointsView normals, const GrassOptions& o, float* out) {
  check_receivers(positions, normals);
  check_grass(o);
  const Vec3 up = normalize(o.up);
  const float ground = o.ground_height, h = o.blade_height, inv_2h = 0.5f / o.blade_height,
              floor = o.floor;
  parallel_for_blocks(positions.size, 16384, [&](std::size_t b, std::size_t e) {
    const float* __restrict p = positions.data;
    const float* __restrict n = normals.data;
    float* __restrict v = out;
    for (std::size_t i = b; i < e; ++i) {
      v[i] = grass_law(p[3 * i], p[3 * i + 1], p[3 * i + 2], n[3 * i], n[3 * i + 1],
                       n[3 * i + 2], up, ground, inv_2h, h, floor);
    }
  });
}

}  // namespace canopy_ao
