// Argument checks shared by the analytic models (declared in model_checks.h). Kept apart from
// canopy_model.cpp, whose hot loops are compiled with finite-math-only: std::isfinite must not
// be folded away here.
#include "canopy_ao/model_checks.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "canopy_ao/canopy_model.h"

namespace canopy_ao {

// === Checks
void check_tau(float tau) {
  if (!std::isfinite(tau) || tau < 0) {
    throw std::invalid_argument("tau must be finite and >= 0, got " + std::to_string(tau));
  }
}

void check_sphere(const Sphere& s) {
  if (!is_finite(s.center)) throw std::invalid_argument("sphere centre is not finite");
  if (!std::isfinite(s.radius) || !(s.radius > 0)) {
    throw std::invalid_argument("sphere radius must be finite and > 0, got " +
                                std::to_string(s.radius));
  }
}

void check_ellipsoid(const Ellipsoid& e) {
  if (!is_finite(e.center)) throw std::invalid_argument("ellipsoid centre is not finite");
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(e.radii[k]) || !(e.radii[k] > 0)) {
      throw std::invalid_argument("ellipsoid radii must be finite and > 0, got " +
                                  std::to_string(e.radii[k]));
    }
    if (!is_finite(e.axes[k]) || std::fabs(dot(e.axes[k], e.axes[k]) - 1.0f) > 2e-3f) {
      throw std::invalid_argument("ellipsoid axes must be unit vectors");
    }
  }
  if (std::fabs(dot(e.axes[0], e.axes[1])) > 1e-3f ||
      std::fabs(dot(e.axes[0], e.axes[2])) > 1e-3f ||
      std::fabs(dot(e.axes[1], e.axes[2])) > 1e-3f) {
    throw std::invalid_argument("ellipsoid axes must be orthogonal");
  }
}

void check_receivers(PointsView positions, PointsView normals) {
  if (positions.size != normals.size) {
    throw std::invalid_argument("positions and normals must have the same number of rows, got " +
                                std::to_string(positions.size) + " and " +
                                std::to_string(normals.size));
  }
  if (positions.size > 0 && (!positions.data || !normals.data)) {
    throw std::invalid_argument("positions/normals data pointer is null");
  }
}

void check_canopy_options(const CanopyOptions& o) {
  check_tau(o.tau);
  if (!std::isfinite(o.band) || o.band < 0) {
    throw std::invalid_argument("band must be finite and >= 0, got " + std::to_string(o.band));
  }
}

}  // namespace canopy_ao
