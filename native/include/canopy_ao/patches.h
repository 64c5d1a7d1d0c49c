// Canopy AO — opaque convex patches (GROUND surfaces: a wall, a rock face, the ground) as
// occluders of the proxy rungs: core/walls.py's visibility, evaluated natively.
#pragma once

#include <cstddef>
#include <vector>

namespace canopy_ao {

/// One plane's opaque polygon: corners in order about `normal` (a unit vector, the side its
/// triangles face), offset = normal · (the corners' mean), diameter = the corners' bounding
/// box diagonal. core/walls.py's Patch.
struct PatchPolygon {
  std::vector<double> corners;  // K × 3
  double normal[3];
  double offset;
  double diameter;
};

/// The AO distance's disc (where a patch's plane meets the sphere of radius D about the
/// receiver) as this many-sided regular polygon of the disc's area (walls.DISC_SIDES).
constexpr int kPatchDiscSides = 8;
/// A receiver within this share of a patch's diameter of its plane is moved that far to its
/// front (walls.EPS): a flat ground sees itself edge-on.
constexpr double kPatchEps = 1e-5;

/// out[i] = clamp(1 − Σ_patches (F(D) − F(near)), 0, 1) for receiver i (positions, normals:
/// N × 3 doubles; unit normals, as F is linear in the normal; a zero one sees nothing), where
/// F(r) is the patch's cosine-weighted form factor (Lambert's contour integral) after clipping
/// it to the receiver's hemisphere and, for a finite r, to the disc its plane cuts from the
/// sphere of radius r (F(near) only when near > 0). distance = inf: no cut. The same numbers
/// as walls.visibility_numpy, in float64 (docs/DESIGN.md, 'How each role is lit'). Parallel
/// over receivers, deterministic. PRE (the bindings check): finite inputs, unit patch normals,
/// every patch ≥ 3 corners, diameter > 0, near >= 0, distance > 0.
void patch_visibility(const std::vector<PatchPolygon>& patches, const double* positions,
                      const double* normals, std::size_t n, double distance, double near,
                      float* out);

}  // namespace canopy_ao
