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
  if (o.layer.empty() && o.layer_rows == 0 && o.layer_cols == 0) return;
  if (o.layer_rows < 2 || o.layer_cols < 2 || o.layer_rows > 4096 || o.layer_cols > 4096 ||
      o.layer.size() != static_cast<std::size_t>(o.layer_rows) * o.layer_cols) {
    throw std::invalid_argument("the blade layer must be rows x cols values with 2 <= rows, "
                                "cols <= 4096, got " + std::to_string(o.layer.size()) +
                                " values for " + std::to_string(o.layer_rows) + " x " +
                                std::to_string(o.layer_cols));
  }
  for (const float v : o.layer) {
    if (!(v >= 0.0f && v <= 1.0f)) {
      throw std::invalid_argument("the blade layer's values must be in [0, 1]");
    }
  }
}

// The blade layer read bilinearly at relative height s ∈ [0, 1] and cos θ ∈ [−1, 1].
inline float layer_at(const GrassOptions& o, float s, float cos_t) {
  const float fi = s * static_cast<float>(o.layer_rows - 1);
  const float fj = 0.5f * (clampf(cos_t, -1.0f, 1.0f) + 1.0f) * static_cast<float>(o.layer_cols - 1);
  const int i = std::min(static_cast<int>(fi), o.layer_rows - 2);
  const int j = std::min(static_cast<int>(fj), o.layer_cols - 2);
  const float a = fi - static_cast<float>(i), b = fj - static_cast<float>(j);
  const float* r0 = o.layer.data() + static_cast<std::size_t>(i) * o.layer_cols + j;
  const float* r1 = r0 + o.layer_cols;
  return (1.0f - a) * ((1.0f - b) * r0[0] + b * r0[1]) + a * ((1.0f - b) * r1[0] + b * r1[1]);
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

// The blade layer at one receiver (grass.h), Pz and cos θ as grass_law.
inline float layer_law(const GrassOptions& o, Vec3 x, Vec3 n, Vec3 up) {
  const float s = clampf((dot(x, up) - o.ground_height) / o.blade_height, 0.0f, 1.0f);
  const float nn = dot(n, n);
  const float cos_t = dot(n, up) / std::sqrt(std::max(nn, 1e-30f));
  return clampf(layer_at(o, s, cos_t), o.floor, 1.0f);
}
}  // namespace

float grass_visibility(Vec3 x, Vec3 n, const GrassOptions& o) {
  check_grass(o);
  const Vec3 up = normalize(o.up);
  if (!o.layer.empty()) return layer_law(o, x, n, up);
  return grass_law(x.x, x.y, x.z, n.x, n.y, n.z, up, o.ground_height, 0.5f / o.blade_height,
                   o.blade_height, o.floor);
}

void ao_grass(PointsView positions, PointsView normals, const GrassOptions& o, float* out) {
  check_receivers(positions, normals);
  check_grass(o);
  const Vec3 up = normalize(o.up);
  if (!o.layer.empty()) {
    parallel_for_blocks(positions.size, 16384, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) out[i] = layer_law(o, positions[i], normals[i], up);
    });
    return;
  }
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
