// Canopy AO — the Reeves–Blau baseline (Reeves & Blau 1985, as compared in Hegeman 2006 §3;
// docs/DESIGN.md, 'The method ladder'): light falls off exponentially with depth inside the
// canopy, whatever the normal.
//
//   V = exp(−τ · depth / R),  depth = max(R − |x − C|, 0)
// evaluated in the ellipsoid's unit frame (R = 1, |x'| = |diag(1/r) Qᵀ(x − C)|), so that τ has
// the canopy model's meaning: V = exp(−τ) at the centre, 1 on and outside the shell.
#pragma once

#include "canopy_ao/geometry.h"

namespace canopy_ao {

/// positions: N×3 (normals are not used by this model); out: N floats in [0, 1].
/// PRE: valid ellipsoid, 0 ≤ τ < ∞ (else std::invalid_argument).
void ao_reeves_blau(PointsView positions, const Ellipsoid& shell, float tau, float* out);

}  // namespace canopy_ao
