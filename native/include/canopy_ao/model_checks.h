// Canopy AO — argument checks shared by the analytic models (canopy_model.h, occluders.h,
// grass.h, reeves_blau.h). Each throws std::invalid_argument naming the problem (Python:
// ValueError). Defined in model_checks.cpp, which is compiled without finite-math-only so
// std::isfinite is never folded away.
#pragma once

#include "canopy_ao/geometry.h"

namespace canopy_ao {

struct CanopyOptions;

/// τ finite and ≥ 0.
void check_tau(float tau);
/// τ as above, band finite and ≥ 0.
void check_canopy_options(const CanopyOptions& o);
/// Finite centre, finite radius > 0.
void check_sphere(const Sphere& s);
/// Finite centre, finite radii > 0, unit orthogonal axes (to 2e-3 / 1e-3).
void check_ellipsoid(const Ellipsoid& e);
/// Same row count; non-null data when non-empty.
void check_receivers(PointsView positions, PointsView normals);

}  // namespace canopy_ao
