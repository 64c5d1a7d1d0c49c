// Canopy AO — world-space receivers and grey colours, one parallel pass each (mesh_arrays.h).
#include "canopy_ao/mesh_arrays.h"

#include <cmath>

#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {

constexpr std::size_t kGrain = 1 << 15;

bool is_identity(const double* m) {
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 4; ++k)
      if (m[4 * i + k] != (i == k ? 1.0 : 0.0)) return false;
  return true;
}

void unit_normal(float* n) {
  const double x = n[0], y = n[1], z = n[2];
  const double l2 = x * x + y * y + z * z;
  if (!(l2 > 1e-40) || !std::isfinite(l2)) {  // zero, NaN or inf: no direction
    n[0] = 0.0f;
    n[1] = 0.0f;
    n[2] = 1.0f;
  } else if (std::fabs(l2 - 1.0) > kUnitNormalSlack) {
    const double s = 1.0 / std::sqrt(l2);
    n[0] = static_cast<float>(x * s);
    n[1] = static_cast<float>(y * s);
    n[2] = static_cast<float>(z * s);
  }
}

}  // namespace

void to_world_in_place(float* positions, float* normals, std::size_t n, const double* matrix) {
  if (matrix != nullptr && is_identity(matrix)) matrix = nullptr;
  double a[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, t[3] = {0, 0, 0};
  double nm[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // inverse transpose of a
  if (matrix != nullptr) {
    for (int i = 0; i < 3; ++i) {
      for (int k = 0; k < 3; ++k) a[i][k] = matrix[4 * i + k];
      t[i] = matrix[4 * i + 3];
    }
    // inv(A)^T = cof(A) / det(A), cof the cofactor matrix.
    double cof[3][3];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) {
        const int i1 = (i + 1) % 3, i2 = (i + 2) % 3, k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        cof[i][k] = a[i1][k1] * a[i2][k2] - a[i1][k2] * a[i2][k1];
      }
    const double det = a[0][0] * cof[0][0] + a[0][1] * cof[0][1] + a[0][2] * cof[0][2];
    // A singular A (a scale of 0 on an axis) has no inverse; its cofactors still map a
    // face's normal to the normal of the face it becomes (cof(A)(a × b) = Aa × Ab), the
    // geometric normal Cycles shades a flattened mesh's faces with.
    const double scale = det != 0 && std::isfinite(det) ? 1.0 / det : 1.0;
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) nm[i][k] = cof[i][k] * scale;
  }
  const bool move = matrix != nullptr;
  parallel_for_blocks(n, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t r = b; r < e; ++r) {
      float* nr = normals + 3 * r;
      if (move) {
        float* p = positions + 3 * r;
        const double x = p[0], y = p[1], z = p[2];
        const double u = nr[0], v = nr[1], w = nr[2];
        for (int i = 0; i < 3; ++i) {
          p[i] = static_cast<float>(a[i][0] * x + a[i][1] * y + a[i][2] * z + t[i]);
          nr[i] = static_cast<float>(nm[i][0] * u + nm[i][1] * v + nm[i][2] * w);
        }
      }
      unit_normal(nr);
    }
  });
}

void gray_rgba(const float* values, std::size_t n, float* rgba) {
  parallel_for_blocks(n, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const float v = values[i];
      float* c = rgba + 4 * i;
      c[0] = v;
      c[1] = v;
      c[2] = v;
      c[3] = 1.0f;
    }
  });
}

}  // namespace canopy_ao
