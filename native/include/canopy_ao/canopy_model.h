// Canopy AO — the canopy-shell model: Hegeman et al. 2006, "Approximate Ambient Occlusion For
// Trees", Eq. 4–6, with the scale-free optical depth τ, ellipsoids and several shells
// (docs/DESIGN.md, 'The method ladder').
//
// Inside a shell of radius R (work in the unit frame, R = 1), receiver x with unit normal n:
//   c = dot(C − x, n)            signed height of the centre above the tangent plane
//   h = clamp(R + c, 0, 2R)      cap height on the +n side                       (Eq. 4)
//   d² = |C − x|² − c²           off-centre distance² in the plane
//   f = h² / (h² + d²)                                                            (Eq. 5)
//   V = exp(−τ f Vcap/Vhemi),  Vcap/Vhemi = h²(3R − h)/(2R³)                      (Eq. 6)
// so V = exp(−τ) at the centre for any normal and V = 1 on the shell facing out.
// Ellipsoids: x' = diag(1/r) Qᵀ(x − C), n' = normalize(diag(r) Qᵀ n), then the above with R = 1.
//
// Receivers OUTSIDE a shell (|x'| > 1). The in-shell formula is not used there: it would count
// the whole cap beyond the tangent plane at full density however far away the shell is (a point
// 10 R from the shell facing it would still get exp(−2τ)). Outside, the shell is a
// horizon-clipped, cosine-weighted sphere occluder scaled by its opacity (occluders.h,
// occluder_visibility). The two laws do not agree on the surface (e.g. τ = 1, normal facing the
// centre: in-shell e^{-2} = 0.135, occluder 1 − (1 − e^{-4/3}) = 0.264), so in a band
// 1 < |x'| < 1 + band just outside the shell the value is blended with a smoothstep weight:
//   V = (1 − w) V_in + w V_out,  w = smoothstep((|x'| − 1)/band).
// V is therefore continuous everywhere (band > 0); band = 0 gives the hard switch.
//
// Zero-length normals: treated as facing away from the shell centre (n = x − C; at the centre
// itself any normal gives exp(−τ)). Never NaN. All results in [0, 1], 1 = open sky.
//
// Throughput (bench/bench_models.cpp): points are processed in blocks of 16k (parallel) and
// chunks of 256. With AVX2/FMA, per chunk: one pass computing the exponent of 8 points at a
// time (AoS → SoA transpose in registers, rsqrt/rcp + one Newton step instead of sqrt and
// divisions, a flag mask for points outside the shell or with a zero normal) into an L1
// buffer, one fast_exp pass (two passes: the fused loop was ~20% slower, one long dependency
// chain per iteration); ~13 instructions per point, no branch but the loops'. Only a chunk with
// a flag set then compacts those points and gives them the in-shell law, the occluder law
// (fast_acos / fast_atan2_pos) and the blend in one more vectorised pass (~20–30 ns per outside
// point per shell). Arrays beyond the caches (≥ 2M points) are written with non-temporal
// stores. Results do not depend on the thread count (the last partial group of 8 is
// zero-padded and goes through the same code). Figures: bench/README.md, "Model throughput".
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

// === Options
struct CanopyOptions {
  /// Optical depth (≥ 0, finite): AO at a shell's centre = exp(−τ), whatever the scale.
  float tau = 1.0f;
  /// Width of the blend band outside each shell, in shell radii (unit frame), ≥ 0.
  float band = 0.1f;
};

/// How several shells combine (docs/DESIGN.md, 'The method ladder').
enum class ShellCombine {
  Product,  ///< V = Π over all shells of that shell's V (in-shell inside, occluder outside).
  Nearest,  ///< Hegeman §5: the shell whose centre is closest to x alone (gives seams).
};

// === The law
/// Hegeman Eq. 5–6 in the unit frame (R = 1): the exponent τ f Vcap/Vhemi = (τ/2) h⁴(3 − h) /
/// (h² + d²) of a receiver with cap height h ∈ [0, 2] (Eq. 4) and off-centre distance² d² ≥ 0;
/// V = exp(−exponent). The one scalar definition of the law: the portable kernel evaluates it
/// as written, the AVX2 kernel in 8 lanes with rsqrt/rcp and a Newton step, and the tests check
/// both against it (CanopyKernels.*).
inline float hegeman_exponent(float h, float d2, float tau) {
  const float h2 = h * h;
  return (0.5f * tau) * h2 * h2 * (3.0f - h) / std::max(h2 + d2, 1e-30f);
}

// === Kernels: chosen at run time
/// Portable: baseline x86-64-v2 (or the target's own) code. Avx2: AVX2 + FMA code, used where
/// the CPU has both. The results agree to ~1e-6 (tests: CanopyKernels.*).
enum class CanopyKernel { Portable, Avx2 };
/// The kernel the model functions use now: the best this CPU runs, unless CANOPY_AO_KERNEL=
/// portable is set in the environment (read once) or set_canopy_kernel chose another.
CanopyKernel canopy_kernel();
/// Whether this CPU (and this build) can run `k`.
bool canopy_kernel_available(CanopyKernel k);
/// Use `k` from now on (process-wide). std::invalid_argument if this CPU cannot run it.
void set_canopy_kernel(CanopyKernel k);

// === One point (reference path; the array functions give the same values)
/// Visibility of one receiver x (world), normal n (any length), for one shell.
float canopy_visibility(Vec3 x, Vec3 n, const Ellipsoid& shell, const CanopyOptions& options);

// === Arrays. positions, normals: N×3 float32 (world space); out: N floats, written.
/// PRE: positions.size == normals.size; sphere.radius > 0; 0 ≤ τ < ∞; band ≥ 0 (else
/// std::invalid_argument). Coordinates must be finite: not re-checked here (a second pass over
/// the data would cost as much as the model); the Python layer (arrays.h) checks them.
void ao_canopy_sphere(PointsView positions, PointsView normals, const Sphere& sphere,
                      const CanopyOptions& options, float* out);
/// PRE: ellipsoid radii > 0, axes orthonormal (to 1e-3).
void ao_canopy_ellipsoid(PointsView positions, PointsView normals, const Ellipsoid& ellipsoid,
                         const CanopyOptions& options, float* out);
/// PRE: shells non-empty, each valid as above.
void ao_canopy_shells(PointsView positions, PointsView normals,
                      const std::vector<Ellipsoid>& shells, const CanopyOptions& options,
                      ShellCombine combine, float* out);

}  // namespace canopy_ao
