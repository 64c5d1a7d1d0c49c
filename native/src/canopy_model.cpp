// Hot loops must vectorise into few instructions: see fast_math.h for no-trapping-math;
// finite-math-only and no-signed-zeros let min/max become vminps/vmaxps instead of
// compare+blend. Every value here is finite by construction (inputs are checked in
// model_checks.cpp, which is compiled without these options; no inf or NaN is produced).
#pragma GCC optimize("no-trapping-math", "finite-math-only", "no-signed-zeros")

#include "canopy_ao/canopy_model.h"

#include <algorithm>
#ifdef __AVX__
#include <immintrin.h>
#endif
#if defined(__AVX2__) && defined(__FMA__)
#define CANOPY_AO_AVX2 1
#endif
#include <cmath>
#include <cstdint>
#include <limits>

#include "canopy_ao/fast_math.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {

constexpr std::size_t kGrain = 16384;  // points per parallel block
constexpr std::size_t kChunk = 256;    // points per vectorised pass (buffers stay in L1)

// Hegeman Eq. 4–6 in the shell's unit frame (R = 1). u = receiver − centre, n = normal of any
// length. Exact scalar version with every guard: the reference, and the fix-up path.
inline float in_shell_unit(float ux, float uy, float uz, float nx, float ny, float nz,
                           float tau) {
  const float uu = ux * ux + uy * uy + uz * uz;
  float nn = nx * nx + ny * ny + nz * nz;
  // Zero normal: face away from the centre (n = u). At the centre u = 0 too: then c = d = 0,
  // h = 1, f = 1 and V = exp(−τ), which is right for any normal there.
  const bool zero = !(nn > 1e-30f);
  nx = zero ? ux : nx;
  ny = zero ? uy : ny;
  nz = zero ? uz : nz;
  nn = zero ? uu : nn;
  const float inv = 1.0f / std::sqrt(std::max(nn, 1e-30f));
  const float c = -(ux * nx + uy * ny + uz * nz) * inv;  // dot(C − x, n̂)
  const float h = clampf(1.0f + c, 0.0f, 2.0f);          // cap height (Eq. 4)
  const float d2 = std::max(uu - c * c, 0.0f);            // off-centre distance² (Eq. 5)
  const float h2 = h * h;
  const float f = h2 / std::max(h2 + d2, 1e-30f);
  const float cap = 0.5f * h2 * (3.0f - h);  // Vcap / Vhemi = h²(3 − h)/2 (DESIGN 3.1)
  return fast_exp(-tau * f * cap);           // Eq. 6 with k = τ / Vhemi
}

// The same law stripped for the vectorised pass: valid for points inside the shell with a
// non-zero normal (there 1 + c ∈ [0, 2] already, and the two divisions fold into one). Points
// it does not cover are flagged for in_shell_unit / the outside law.
inline float in_shell_fast_exponent(float ux, float uy, float uz, float nx, float ny, float nz,
                           float tau, int& flag) {
  const float uu = ux * ux + uy * uy + uz * uz;
  const float nn = nx * nx + ny * ny + nz * nz;
  const float inv = 1.0f / std::sqrt(nn + 1e-30f);
  const float c = -(ux * nx + uy * ny + uz * nz) * inv;
  const float h = 1.0f + c;
  const float h2 = h * h;
  const float d2 = std::max(uu - c * c, 0.0f);
  // τ f Vcap/Vhemi = τ · h²/(h² + d²) · h²(3 − h)/2
  const float e = (0.5f * tau) * h2 * h2 * (3.0f - h) / (h2 + d2 + 1e-30f);
  flag = (uu > 1.0f) | (nn < 1e-30f);
  return -e;  // the exponent; exp is taken in a second pass (see shell_chunk)
}

// World → unit frame of a sphere: u = (p − C)/R; normals unchanged (uniform scale).
struct SphereMap {
  float cx, cy, cz, inv_r;
  explicit SphereMap(const Sphere& s)
      : cx(s.center.x), cy(s.center.y), cz(s.center.z), inv_r(1.0f / s.radius) {}
  void operator()(float px, float py, float pz, float qx, float qy, float qz, float& ux,
                  float& uy, float& uz, float& nx, float& ny, float& nz) const {
    ux = (px - cx) * inv_r;
    uy = (py - cy) * inv_r;
    uz = (pz - cz) * inv_r;
    nx = qx;
    ny = qy;
    nz = qz;
  }
#ifdef CANOPY_AO_AVX2
  // The same, 8 points at a time (same operations, so the same roundings).
  void v8(__m256 px, __m256 py, __m256 pz, __m256 qx, __m256 qy, __m256 qz, __m256& ux,
          __m256& uy, __m256& uz, __m256& nx, __m256& ny, __m256& nz) const {
    const __m256 r = _mm256_set1_ps(inv_r);
    ux = _mm256_mul_ps(_mm256_sub_ps(px, _mm256_set1_ps(cx)), r);
    uy = _mm256_mul_ps(_mm256_sub_ps(py, _mm256_set1_ps(cy)), r);
    uz = _mm256_mul_ps(_mm256_sub_ps(pz, _mm256_set1_ps(cz)), r);
    nx = qx;
    ny = qy;
    nz = qz;
  }
#endif
};

// World → unit frame of an ellipsoid (DESIGN 3.2): u = diag(1/r) Qᵀ(p − C),
// n' = diag(r) Qᵀ n (inverse transpose; normalised in in_shell_unit).
struct EllipsoidMap {
  float c[3];
  float m[9];   // rows a_k / r_k
  float nm[9];  // rows a_k · r_k
  explicit EllipsoidMap(const Ellipsoid& e) {
    for (int k = 0; k < 3; ++k) {
      c[k] = e.center[k];
      for (int j = 0; j < 3; ++j) {
        m[3 * k + j] = e.axes[k][j] / e.radii[k];
        nm[3 * k + j] = e.axes[k][j] * e.radii[k];
      }
    }
  }
  void operator()(float px, float py, float pz, float qx, float qy, float qz, float& ux,
                  float& uy, float& uz, float& nx, float& ny, float& nz) const {
    const float dx = px - c[0], dy = py - c[1], dz = pz - c[2];
    ux = m[0] * dx + m[1] * dy + m[2] * dz;
    uy = m[3] * dx + m[4] * dy + m[5] * dz;
    uz = m[6] * dx + m[7] * dy + m[8] * dz;
    nx = nm[0] * qx + nm[1] * qy + nm[2] * qz;
    ny = nm[3] * qx + nm[4] * qy + nm[5] * qz;
    nz = nm[6] * qx + nm[7] * qy + nm[8] * qz;
  }
#ifdef CANOPY_AO_AVX2
  static __m256 row(const float* a, __m256 x, __m256 y, __m256 z) {
    return _mm256_fmadd_ps(_mm256_set1_ps(a[2]), z,
                           _mm256_fmadd_ps(_mm256_set1_ps(a[1]), y,
                                           _mm256_mul_ps(_mm256_set1_ps(a[0]), x)));
  }
  void v8(__m256 px, __m256 py, __m256 pz, __m256 qx, __m256 qy, __m256 qz, __m256& ux,
          __m256& uy, __m256& uz, __m256& nx, __m256& ny, __m256& nz) const {
    const __m256 dx = _mm256_sub_ps(px, _mm256_set1_ps(c[0]));
    const __m256 dy = _mm256_sub_ps(py, _mm256_set1_ps(c[1]));
    const __m256 dz = _mm256_sub_ps(pz, _mm256_set1_ps(c[2]));
    ux = row(m, dx, dy, dz);
    uy = row(m + 3, dx, dy, dz);
    uz = row(m + 6, dx, dy, dz);
    nx = row(nm, qx, qy, qz);
    ny = row(nm + 3, qx, qy, qz);
    nz = row(nm + 6, qx, qy, qz);
  }
#endif
};

// AoS (count × 3) → three SoA arrays. GCC vectorises a stride-3 loop with long vpermd/blend
// chains (about 1 ns per point for positions + normals here, as much as the whole model); with
// AVX, the classic 8-point transpose takes 6 half-loads and 5 in-lane shuffles per array.
inline void deinterleave(const float* __restrict a, std::size_t count, float* __restrict x,
                         float* __restrict y, float* __restrict z) {
  std::size_t i = 0;
#ifdef __AVX__
  for (; i + 8 <= count; i += 8) {
    const float* q = a + 3 * i;
    __m256 m03 = _mm256_castps128_ps256(_mm_loadu_ps(q));       // x0 y0 z0 x1 | x4 y4 z4 x5
    __m256 m14 = _mm256_castps128_ps256(_mm_loadu_ps(q + 4));   // y1 z1 x2 y2 | y5 z5 x6 y6
    __m256 m25 = _mm256_castps128_ps256(_mm_loadu_ps(q + 8));   // z2 x3 y3 z3 | z6 x7 y7 z7
    m03 = _mm256_insertf128_ps(m03, _mm_loadu_ps(q + 12), 1);
    m14 = _mm256_insertf128_ps(m14, _mm_loadu_ps(q + 16), 1);
    m25 = _mm256_insertf128_ps(m25, _mm_loadu_ps(q + 20), 1);
    const __m256 xy = _mm256_shuffle_ps(m14, m25, _MM_SHUFFLE(2, 1, 3, 2));  // x2 y2 x3 y3
    const __m256 yz = _mm256_shuffle_ps(m03, m14, _MM_SHUFFLE(1, 0, 2, 1));  // y0 z0 y1 z1
    _mm256_storeu_ps(x + i, _mm256_shuffle_ps(m03, xy, _MM_SHUFFLE(2, 0, 3, 0)));
    _mm256_storeu_ps(y + i, _mm256_shuffle_ps(yz, xy, _MM_SHUFFLE(3, 1, 2, 0)));
    _mm256_storeu_ps(z + i, _mm256_shuffle_ps(yz, m25, _MM_SHUFFLE(3, 0, 3, 1)));
  }
#endif
  for (; i < count; ++i) {
    x[i] = a[3 * i];
    y[i] = a[3 * i + 1];
    z[i] = a[3 * i + 2];
  }
}

// Everything one shell needs per chunk.
template <class Map>
struct ShellEval {
  Map map;
  Ellipsoid shell;  // world shape, for the outside (occluder) law
  float tau, band, opacity;
};

// The occluder law of occluders.h (occluder_visibility) for a receiver outside the shell,
// branch-free so that the fix-up pass vectorises: the sphere with the shell's projected area
// seen from x, Snyder's horizon-clipped form with fast_acos / fast_atan2_pos. Tested against
// occluder_visibility (CanopyEllipsoid.OutsideMatchesOccluderLaw).
inline float outside_law(float x, float y, float z, float nx, float ny, float nz,
                         const Ellipsoid& e, float opacity) {
  const float nn = nx * nx + ny * ny + nz * nz;
  const float dx = e.center.x - x, dy = e.center.y - y, dz = e.center.z - z;
  const float inv_d = 1.0f / std::sqrt(dx * dx + dy * dy + dz * dz + 1e-30f);
  const float c = clampf((nx * dx + ny * dy + nz * dz) * inv_d / std::sqrt(nn + 1e-30f), -1.0f,
                         1.0f);
  float q = 0;
  for (int k = 0; k < 3; ++k) {
    const float t = (dx * e.axes[k].x + dy * e.axes[k].y + dz * e.axes[k].z) * inv_d *
                    (e.radii.z / e.radii[k]);
    q += t * t;
  }
  const float s2 = std::min((e.radii.x * inv_d) * (e.radii.y * inv_d) * std::sqrt(q), 1.0f);
  // Snyder / Frostbite, as sphere_occlusion, every branch computed and selected.
  const float s = std::sqrt(std::max(1.0f - c * c, 0.0f));
  const float xs = std::sqrt(std::max(1.0f / s2 - 1.0f, 0.0f));
  const float yv = clampf(-xs * c / std::max(s, 1e-20f), -1.0f, 1.0f);
  const float sy = std::sqrt(std::max(1.0f - yv * yv, 0.0f));
  const float crossing =
      clampf(((c * fast_acos(yv) - xs * s * sy) * s2 + fast_atan2_pos(s * sy, xs)) *
                 0.318309886183791f,
             0.0f, 1.0f);
  const float clear = std::max(c, 0.0f) * s2;  // wholly above (or below: 0) the horizon
  float occ = c * c > s2 ? clear : crossing;
  occ = s2 >= 1.0f ? 0.5f * (1.0f + c) : occ;  // on the shell: the half-space
  occ = nn < 1e-30f ? 0.0f : occ;               // zero normal: faces away, nothing blocked
  return clampf(1.0f - opacity * occ, 0.0f, 1.0f);
}

// In-shell law, occluder law and their blend across the band, for m points given as SoA
// (px..qz, world space); branch-free so that it vectorises. Both fix-up paths use it.
template <class Map>
void blend_points(const ShellEval<Map>& s, const float* px, const float* py, const float* pz,
                  const float* qx, const float* qy, const float* qz, std::size_t m,
                  float* __restrict out) {
  const float tau = s.tau;
  const float band = s.band, inv_band = band > 0 ? 1.0f / band : 0.0f, opacity = s.opacity;
  const Ellipsoid& shell = s.shell;
  for (std::size_t j = 0; j < m; ++j) {
    float ux, uy, uz, nx, ny, nz;
    s.map(px[j], py[j], pz[j], qx[j], qy[j], qz[j], ux, uy, uz, nx, ny, nz);
    const float s2 = ux * ux + uy * uy + uz * uz;
    const float v_in = in_shell_unit(ux, uy, uz, nx, ny, nz, tau);
    const float v_out = outside_law(px[j], py[j], pz[j], qx[j], qy[j], qz[j], shell, opacity);
    const float outside = s2 > 1.0f ? 1.0f : 0.0f;
    const float w = band > 0 ? smoothstep01((std::sqrt(s2) - 1.0f) * inv_band) : outside;
    out[j] = clampf((1.0f - w) * v_in + w * v_out, 0.0f, 1.0f);
  }
}

#ifdef CANOPY_AO_AVX2

// fast_exp (fast_math.h), 8 lanes: the same reduction and polynomial.
inline __m256 fast_exp8(__m256 x) {
  const __m256 lo = _mm256_set1_ps(-87.3f);
  const __m256 xc = _mm256_min_ps(_mm256_max_ps(x, lo), _mm256_set1_ps(88.3f));
  const __m256 shifter = _mm256_set1_ps(12582912.0f);
  const __m256 ks = _mm256_fmadd_ps(xc, _mm256_set1_ps(1.44269504088896341f), shifter);
  const __m256 kf = _mm256_sub_ps(ks, shifter);
  __m256 r = _mm256_fnmadd_ps(kf, _mm256_set1_ps(0.693359375f), xc);
  r = _mm256_fnmadd_ps(kf, _mm256_set1_ps(-2.12194440e-4f), r);
  const __m256 r2 = _mm256_mul_ps(r, r);
  __m256 q = _mm256_set1_ps(1.9875691500e-4f);
  q = _mm256_fmadd_ps(q, r, _mm256_set1_ps(1.3981999507e-3f));
  q = _mm256_fmadd_ps(q, r, _mm256_set1_ps(8.3334519073e-3f));
  q = _mm256_fmadd_ps(q, r, _mm256_set1_ps(4.1665795894e-2f));
  q = _mm256_fmadd_ps(q, r, _mm256_set1_ps(1.6666665459e-1f));
  q = _mm256_fmadd_ps(q, r, _mm256_set1_ps(5.0000001201e-1f));
  q = _mm256_add_ps(_mm256_fmadd_ps(q, r2, r), _mm256_set1_ps(1.0f));
  const __m256i bits = _mm256_slli_epi32(
      _mm256_sub_epi32(_mm256_castps_si256(ks), _mm256_set1_epi32(0x4B400000 - 127)), 23);
  const __m256 y = _mm256_mul_ps(q, _mm256_castsi256_ps(bits));
  return _mm256_andnot_ps(_mm256_cmp_ps(x, lo, _CMP_LT_OQ), y);  // 0 below -87.3
}

// in_shell_fast_exponent for 8 AoS points, in registers. The divider is the
// bottleneck of the scalar form (one sqrt and two divisions per point, ~15 cycles per 8 on
// this CPU): here 1/√(n·n) is rsqrt plus one Newton step and the one division left is rcp plus
// one Newton step on the quotient (both ~1e-7 relative, well inside the tested accuracy).
// flags: bit k set when point k is outside the shell or has a zero normal (fix-up path).
template <class Map>
inline __m256 in_shell_fast8(const Map& map, const float* p, const float* n, __m256 half_tau,
                             int& flags) {
  __m256 px, py, pz, qx, qy, qz, ux, uy, uz, nx, ny, nz;
  load8_aos(p, px, py, pz);
  load8_aos(n, qx, qy, qz);
  map.v8(px, py, pz, qx, qy, qz, ux, uy, uz, nx, ny, nz);
  const __m256 uu = _mm256_fmadd_ps(uz, uz, _mm256_fmadd_ps(uy, uy, _mm256_mul_ps(ux, ux)));
  const __m256 nn = _mm256_fmadd_ps(nz, nz, _mm256_fmadd_ps(ny, ny, _mm256_mul_ps(nx, nx)));
  const __m256 un = _mm256_fmadd_ps(uz, nz, _mm256_fmadd_ps(uy, ny, _mm256_mul_ps(ux, nx)));
  const __m256 tiny = _mm256_set1_ps(1e-30f);
  const __m256 nnc = _mm256_max_ps(nn, tiny);
  __m256 inv = _mm256_rsqrt_ps(nnc);  // y ← y (3 − x y²) / 2
  inv = _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(0.5f), inv),
                      _mm256_fnmadd_ps(_mm256_mul_ps(nnc, inv), inv, _mm256_set1_ps(3.0f)));
  const __m256 g = _mm256_mul_ps(un, inv);  // −c = dot(x − C, n̂)
  const __m256 h = _mm256_sub_ps(_mm256_set1_ps(1.0f), g);
  const __m256 h2 = _mm256_mul_ps(h, h);
  const __m256 d2 = _mm256_max_ps(_mm256_fnmadd_ps(g, g, uu), _mm256_setzero_ps());
  // τ f Vcap/Vhemi = (τ/2) · h⁴ (3 − h) / (h² + d²)
  const __m256 num = _mm256_mul_ps(_mm256_mul_ps(half_tau, _mm256_mul_ps(h2, h2)),
                                   _mm256_sub_ps(_mm256_set1_ps(3.0f), h));
  const __m256 den = _mm256_max_ps(_mm256_add_ps(h2, d2), tiny);
  const __m256 r0 = _mm256_rcp_ps(den);
  const __m256 e0 = _mm256_mul_ps(num, r0);
  const __m256 e = _mm256_fmadd_ps(r0, _mm256_fnmadd_ps(den, e0, num), e0);  // Newton step
  const __m256 bad = _mm256_or_ps(_mm256_cmp_ps(uu, _mm256_set1_ps(1.0f), _CMP_GT_OQ),
                                  _mm256_cmp_ps(nn, tiny, _CMP_LT_OQ));
  flags = _mm256_movemask_ps(bad);
  return _mm256_sub_ps(_mm256_setzero_ps(), e);  // the exponent; fast_exp8 in a second pass
}

// The fix-up of the flagged points (outside the shell, or a zero normal): in-shell law,
// occluder law and blend, branch-free, for the m points idx[0..m) of the chunk at p/n; the
// results go to v[idx[j]].
template <class Map>
void fix_up(const ShellEval<Map>& s, const float* __restrict p, const float* __restrict n,
            const int* idx, std::size_t m, float* __restrict v) {
  alignas(32) float px[kChunk], py[kChunk], pz[kChunk], qx[kChunk], qy[kChunk], qz[kChunk];
  float out[kChunk];
  for (std::size_t j = 0; j < m; ++j) {
    const std::size_t i = static_cast<std::size_t>(idx[j]);
    px[j] = p[3 * i], py[j] = p[3 * i + 1], pz[j] = p[3 * i + 2];
    qx[j] = n[3 * i], qy[j] = n[3 * i + 1], qz[j] = n[3 * i + 2];
  }
  blend_points(s, px, py, pz, qx, qy, qz, m, out);
  for (std::size_t j = 0; j < m; ++j) v[idx[j]] = out[j];
}

// V of one shell for `count` ≤ kChunk points starting at p/n (AoS). One fused vectorised pass
// over groups of 8 (the last partial group zero-padded, so every point, in any block, goes
// through the same code and gets the same value), keeping a flag mask per group; then, only if
// a flag is set, the fix-up of those points. stream: v is 16-byte aligned and the results go
// out with non-temporal stores (arrays far larger than the caches: saves the read-for-ownership
// of the output lines); the caller issues the sfence.
template <class Map>
void shell_chunk(const ShellEval<Map>& s, const float* __restrict p, const float* __restrict n,
                 std::size_t count, float* __restrict v, bool stream = false) {
  alignas(32) float res[kChunk];
  int flags[kChunk / 8];
  const __m256 half_tau = _mm256_set1_ps(0.5f * s.tau);
  const std::size_t full = count & ~std::size_t{7};
  int any = 0;
  // Pass 1: the exponent of every point into res (L1). Pass 2: its exponential. Fused, each
  // iteration is one ~100-instruction dependency chain (transpose → rsqrt → Newton → rcp →
  // Newton → polynomial) and too few iterations fit in the out-of-order window: measured ~20%
  // slower per point than the two passes.
  for (std::size_t i = 0; i < full; i += 8) {
    int f;
    _mm256_store_ps(res + i, in_shell_fast8(s.map, p + 3 * i, n + 3 * i, half_tau, f));
    flags[i / 8] = f;
    any |= f;
  }
  if (full < count) {
    const std::size_t rem = count - full;
    alignas(32) float pp[24] = {}, qq[24] = {};
    std::copy(p + 3 * full, p + 3 * count, pp);
    std::copy(n + 3 * full, n + 3 * count, qq);
    int f;
    _mm256_store_ps(res + full, in_shell_fast8(s.map, pp, qq, half_tau, f));
    f &= (1 << rem) - 1;
    flags[full / 8] = f;
    any |= f;
  }
  float* dst = stream ? res : v;
  for (std::size_t i = 0; i < full; i += 8)
    _mm256_storeu_ps(dst + i, fast_exp8(_mm256_load_ps(res + i)));
  if (full < count) {
    _mm256_store_ps(res + full, fast_exp8(_mm256_load_ps(res + full)));
    if (!stream) std::copy(res + full, res + count, v + full);
  }
  if (any) {
    int idx[kChunk] = {};  // (zeroed only on this rare path: silences -Wmaybe-uninitialized)
    std::size_t m = 0;
    for (std::size_t g = 0; g < (count + 7) / 8; ++g) {
      for (unsigned f = static_cast<unsigned>(flags[g]); f; f &= f - 1)
        idx[m++] = static_cast<int>(8 * g) + __builtin_ctz(f);
    }
    fix_up(s, p, n, idx, m, dst);
  }
  if (stream) {  // v is 16-byte aligned (malloc's and numpy's guarantee), maybe 32
    if (reinterpret_cast<std::uintptr_t>(v) % 32 == 0) {
      for (std::size_t i = 0; i < full; i += 8) _mm256_stream_ps(v + i, _mm256_load_ps(res + i));
    } else {
      for (std::size_t i = 0; i < full; i += 4) _mm_stream_ps(v + i, _mm_load_ps(res + i));
    }
    std::copy(res + full, res + count, v + full);
  }
}
#else
// V of one shell for `count` points starting at p/n (AoS). One vectorised in-shell pass, then a
// scalar fix-up of the (usually few) points outside the shell.
template <class Map>
void shell_chunk(const ShellEval<Map>& s, const float* __restrict p, const float* __restrict n,
                 std::size_t count, float* __restrict v, bool /*stream*/ = false) {
  int flag[kChunk];
  alignas(32) float px[kChunk], py[kChunk], pz[kChunk], qx[kChunk], qy[kChunk], qz[kChunk];
  deinterleave(p, count, px, py, pz);
  deinterleave(n, count, qx, qy, qz);
  const float tau = s.tau;
  // Unrolled twice: two independent sqrt → div → div chains in flight (+6% measured).
#pragma GCC unroll 2
  for (std::size_t i = 0; i < count; ++i) {
    float ux, uy, uz, nx, ny, nz;
    s.map(px[i], py[i], pz[i], qx[i], qy[i], qz[i], ux, uy, uz, nx, ny, nz);
    v[i] = in_shell_fast_exponent(ux, uy, uz, nx, ny, nz, tau, flag[i]);
  }
  // Two short loops rather than one long one: each iteration of the fused loop is one long
  // dependency chain (sqrt → div → div → polynomial) and too few of them fit in the
  // out-of-order window; split, each pass runs near its throughput limit.
  for (std::size_t i = 0; i < count; ++i) v[i] = fast_exp(v[i]);
  int any = 0;  // an int OR-reduction vectorises
  for (std::size_t i = 0; i < count; ++i) any |= flag[i];
  if (!any) return;
  // Fix-up of the flagged points (outside the shell, or a zero normal), vectorised too:
  // compact them, evaluate in-shell law, occluder law and blend branch-free, scatter back.
  int idx[kChunk];
  std::size_t m = 0;
  for (std::size_t i = 0; i < count; ++i) {
    if (!flag[i]) continue;
    idx[m] = static_cast<int>(i);
    px[m] = px[i], py[m] = py[i], pz[m] = pz[i];  // m ≤ i: compaction in place is safe
    qx[m] = qx[i], qy[m] = qy[i], qz[m] = qz[i];
    ++m;
  }
  float out[kChunk];
  blend_points(s, px, py, pz, qx, qy, qz, m, out);
  for (std::size_t j = 0; j < m; ++j) v[idx[j]] = out[j];
}

#endif

template <class Map>
ShellEval<Map> make_eval(const Map& map, const Ellipsoid& shell, const CanopyOptions& o) {
  return ShellEval<Map>{map, shell, o.tau, o.band, shell_opacity(o.tau)};
}


// Non-temporal output stores from this many points on (input + output ≥ 56 MB, beyond the
// last-level cache) when `out` is 16-byte aligned (chunks start at multiples of 8 points).
constexpr std::size_t kStreamFrom = std::size_t{1} << 21;

template <class Map>
void run_one_shell(PointsView positions, PointsView normals, const ShellEval<Map>& eval,
                   float* out) {
#ifdef CANOPY_AO_AVX2
  const bool stream =
      positions.size >= kStreamFrom && reinterpret_cast<std::uintptr_t>(out) % 16 == 0;
#else
  const bool stream = false;
#endif
  parallel_for_blocks(positions.size, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; i += kChunk) {
      const std::size_t cnt = std::min(kChunk, e - i);
      shell_chunk(eval, positions.data + 3 * i, normals.data + 3 * i, cnt, out + i, stream);
    }
#ifdef CANOPY_AO_AVX2
    if (stream) _mm_sfence();
#endif
  });
}

}  // namespace

// === One point
float canopy_visibility(Vec3 x, Vec3 n, const Ellipsoid& shell, const CanopyOptions& options) {
  check_canopy_options(options);
  check_ellipsoid(shell);
  const float p[3] = {x.x, x.y, x.z};
  const float nn[3] = {n.x, n.y, n.z};
  float v;
  shell_chunk(make_eval(EllipsoidMap(shell), shell, options), p, nn, 1, &v);
  return v;
}

// === Arrays
void ao_canopy_sphere(PointsView positions, PointsView normals, const Sphere& sphere,
                      const CanopyOptions& options, float* out) {
  check_receivers(positions, normals);
  check_sphere(sphere);
  check_canopy_options(options);
  run_one_shell(positions, normals,
                make_eval(SphereMap(sphere), Ellipsoid::from_sphere(sphere), options), out);
}

void ao_canopy_ellipsoid(PointsView positions, PointsView normals, const Ellipsoid& ellipsoid,
                         const CanopyOptions& options, float* out) {
  check_receivers(positions, normals);
  check_ellipsoid(ellipsoid);
  check_canopy_options(options);
  run_one_shell(positions, normals, make_eval(EllipsoidMap(ellipsoid), ellipsoid, options), out);
}

void ao_canopy_shells(PointsView positions, PointsView normals,
                      const std::vector<Ellipsoid>& shells, const CanopyOptions& options,
                      ShellCombine combine, float* out) {
  check_receivers(positions, normals);
  check_canopy_options(options);
  if (shells.empty()) throw std::invalid_argument("shells must not be empty");
  for (const Ellipsoid& s : shells) check_ellipsoid(s);
  std::vector<ShellEval<EllipsoidMap>> evals;
  evals.reserve(shells.size());
  for (const Ellipsoid& s : shells) evals.push_back(make_eval(EllipsoidMap(s), s, options));

  parallel_for_blocks(positions.size, kGrain, [&](std::size_t b, std::size_t e) {
    float tmp[kChunk];
    int nearest[kChunk];
    float best[kChunk];
    for (std::size_t i = b; i < e; i += kChunk) {
      const std::size_t cnt = std::min(kChunk, e - i);
      const float* p = positions.data + 3 * i;
      const float* n = normals.data + 3 * i;
      float* v = out + i;
      if (combine == ShellCombine::Product) {
        shell_chunk(evals[0], p, n, cnt, v);
        for (std::size_t k = 1; k < evals.size(); ++k) {
          shell_chunk(evals[k], p, n, cnt, tmp);
          for (std::size_t j = 0; j < cnt; ++j) v[j] *= tmp[j];
        }
      } else {
        // Hegeman §5: the shell with the closest centre (first one on ties).
        for (std::size_t j = 0; j < cnt; ++j) {
          nearest[j] = 0;
          best[j] = std::numeric_limits<float>::infinity();
        }
        for (std::size_t k = 0; k < shells.size(); ++k) {
          const Vec3 c = shells[k].center;
          for (std::size_t j = 0; j < cnt; ++j) {
            const float dx = p[3 * j] - c.x, dy = p[3 * j + 1] - c.y, dz = p[3 * j + 2] - c.z;
            const float d2 = dx * dx + dy * dy + dz * dz;
            if (d2 < best[j]) {
              best[j] = d2;
              nearest[j] = static_cast<int>(k);
            }
          }
        }
        for (std::size_t k = 0; k < evals.size(); ++k) {
          shell_chunk(evals[k], p, n, cnt, tmp);
          for (std::size_t j = 0; j < cnt; ++j) {
            if (nearest[j] == static_cast<int>(k)) v[j] = tmp[j];
          }
        }
      }
    }
  });
}

}  // namespace canopy_ao
