// Hot loops must vectorise: see fast_math.h for why this pragma is here.
#pragma GCC optimize("no-trapping-math")

#include "canopy_ao/reeves_blau.h"

#include <algorithm>
#include <cmath>

#include "canopy_ao/model_checks.h"
#include "canopy_ao/fast_math.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

void ao_reeves_blau(PointsView positions, const Ellipsoid& shell, float tau, float* out) {
  check_ellipsoid(shell);
  check_tau(tau);
  float m[9], c[3];
  for (int k = 0; k < 3; ++k) {
    c[k] = shell.center[k];
    for (int j = 0; j < 3; ++j) m[3 * k + j] = shell.axes[k][j] / shell.radii[k];
  }
  parallel_for_blocks(positions.size, 16384, [&](std::size_t b, std::size_t e) {
    const float* __restrict p = positions.data;
    float* __restrict v = out;
    for (std::size_t i = b; i < e; ++i) {
      const float dx = p[3 * i] - c[0], dy = p[3 * i + 1] - c[1], dz = p[3 * i + 2] - c[2];
      const float ux = m[0] * dx + m[1] * dy + m[2] * dz;
      const float uy = m[3] * dx + m[4] * dy + m[5] * dz;
      const float uz = m[6] * dx + m[7] * dy + m[8] * dz;
      const float depth = std::max(1.0f - std::sqrt(ux * ux + uy * uy + uz * uz), 0.0f);
      v[i] = fast_exp(-tau * depth);  // depth in shell radii (unit frame)
    }
  });
}

}  // namespace canopy_ao
