// Canopy AO — elementary functions that GCC auto-vectorises.
//
// libm's expf is a call GCC cannot vectorise (without -ffast-math and libmvec), which costs the
// one-sphere model a factor ~8 (docs/DESIGN.md, 'Facts measured in Blender': 170 M vs 1.3 G vertices/s per core). These versions
// are branch-free straight-line code: inlined into a simple loop they become vector code, AVX2/FMA
// where the loop is in an AVX2 function (CANOPY_AO_TARGET_AVX2, canopy_model.cpp's kernels).
//
// GCC 12 caveat: with the default -ftrapping-math a clamp against a constant followed by
// arithmetic is turned into a conditional multiply that "could trap", and the loop is not
// if-converted. Translation units with hot loops therefore start with
// `#pragma GCC optimize("no-trapping-math")` (we never enable FP exceptions); a global
// -fno-trapping-math in CMake would do the same. Check with -fopt-info-vec-optimized.
//
// Accuracy (checked by tests/cpp/test_canopy_model.cpp, FastMath.*):
//   fast_exp: max relative error < 1e-6 (measured 8.3e-8, about 1 ulp) on [-87.3, 88.3];
//             0 for x < -87.3 (true value < 1.2e-38, below the normal float range);
//             x > 88.3 gives e^88.3 ≈ 2.2e38 (never inf). NaN input: unspecified (callers
//             validate their inputs).
//   fast_acos: |error| < 1e-6 (measured 4e-7) on [-1, 1];
//   fast_atan2_pos: |error| < 1e-6 (measured 1.4e-7) on the first quadrant.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
/// x86: AVX2/FMA kernels are compiled besides the baseline ones and chosen at run time.
#define CANOPY_AO_X86 1
/// Marks a function as AVX2/FMA code: call it only where cpu_has_avx2_fma() is true.
#define CANOPY_AO_TARGET_AVX2 __attribute__((target("avx2,fma")))
#endif

namespace canopy_ao {

/// Clamp to [lo, hi], written so that it maps to min/max instructions.
inline float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }

/// e^x in float, vectorisable. Cody–Waite reduction x = k·ln2 + r, |r| ≤ ln2/2, then Cephes'
/// degree-6 polynomial for e^r (the one in Cephes expf), then scaling by 2^k through the
/// exponent bits.
inline float fast_exp(float x) {
  // Clamp so that 2^k stays a normal float (k in [-126, 127]).
  const float xc = clampf(x, -87.3f, 88.3f);
  // Round x·log2(e) to nearest with the 1.5·2^23 shifter (exact in round-to-nearest mode);
  // the shifted value's low mantissa bits hold k itself, which avoids a float→int conversion
  // (GCC will not if-convert a possibly trapping conversion, and the loop would not vectorise).
  const float shifter = 12582912.0f;
  const float ks = xc * 1.44269504088896341f + shifter;
  const float kf = ks - shifter;
  float r = xc - kf * 0.693359375f;  // ln2 split: hi part has few bits, so k·hi is exact
  r = r - kf * -2.12194440e-4f;
  const float r2 = r * r;
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  p = p * r2 + r + 1.0f;
  std::int32_t kbits;
  std::memcpy(&kbits, &ks, sizeof kbits);
  const std::int32_t bits = (kbits - 0x4B400000 + 127) << 23;  // 2^k
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  const float y = p * scale;
  return x < -87.3f ? 0.0f : y;
}

/// acos(y) for y in [-1, 1], vectorisable: Abramowitz & Stegun 4.4.46,
/// acos|y| = sqrt(1 − |y|)·P₇(|y|) (|error| ≤ 2e-8 in exact arithmetic), reflected for y < 0.
inline float fast_acos(float y) {
  const float a = y < 0 ? -y : y;
  float p = -0.0012624911f;
  p = p * a + 0.0066700901f;
  p = p * a - 0.0170881256f;
  p = p * a + 0.0308918810f;
  p = p * a - 0.0501743046f;
  p = p * a + 0.0889789874f;
  p = p * a - 0.2145988016f;
  p = p * a + 1.5707963050f;
  const float r = std::sqrt(1.0f - (a > 1.0f ? 1.0f : a)) * p;
  return y < 0 ? 3.14159265358979f - r : r;
}

/// atan2(a, b) for a ≥ 0, b ≥ 0 (the first quadrant), vectorisable: Cephes atanf's reduction
/// of t = a/b to |t| ≤ tan(π/8) and its degree-9 odd polynomial (error ~1e-7).
/// atan2(0, 0) = 0.
inline float fast_atan2_pos(float a, float b) {
  const float t = a / (b > 1e-30f ? b : 1e-30f);
  const bool big = t > 2.414213562373095f;   // tan(3π/8)
  const bool mid = t > 0.4142135623730950f;  // tan(π/8)
  const float x = big ? -1.0f / (t > 1e-30f ? t : 1e-30f) : (mid ? (t - 1.0f) / (t + 1.0f) : t);
  const float y0 = big ? 1.5707963267948966f : (mid ? 0.7853981633974483f : 0.0f);
  const float z = x * x;
  const float p =
      (((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z -
       3.33329491539e-1f) * z * x + x;
  return y0 + p;
}

/// Hermite smoothstep on [0, 1]: 0 for t ≤ 0, 1 for t ≥ 1, C¹ in between.
inline float smoothstep01(float t) {
  const float u = clampf(t, 0.0f, 1.0f);
  return u * u * (3.0f - 2.0f * u);
}

#ifdef CANOPY_AO_X86
/// Whether this CPU runs AVX2 and FMA instructions (the OS saving the YMM state included).
inline bool cpu_has_avx2_fma() {
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

/// 8 AoS xyz points (24 floats at q, unaligned) → x, y, z registers: the transpose of an N×3
/// array done in registers (6 half-loads, 5 in-lane shuffles), without a trip through memory.
/// Used by the canopy models and by the benchmark's bare-loop ceiling (same loads in both).
// always_inline: GCC does not inline a function with its own target attribute into a caller
// whose target comes from a pragma (the flag sets differ slightly), and a call per 8 points
// costs the model a quarter of its speed (measured).
CANOPY_AO_TARGET_AVX2 __attribute__((always_inline)) inline void load8_aos(const float* q, __m256& x, __m256& y, __m256& z) {
  __m256 m03 = _mm256_castps128_ps256(_mm_loadu_ps(q));
  __m256 m14 = _mm256_castps128_ps256(_mm_loadu_ps(q + 4));
  __m256 m25 = _mm256_castps128_ps256(_mm_loadu_ps(q + 8));
  m03 = _mm256_insertf128_ps(m03, _mm_loadu_ps(q + 12), 1);
  m14 = _mm256_insertf128_ps(m14, _mm_loadu_ps(q + 16), 1);
  m25 = _mm256_insertf128_ps(m25, _mm_loadu_ps(q + 20), 1);
  const __m256 xy = _mm256_shuffle_ps(m14, m25, _MM_SHUFFLE(2, 1, 3, 2));
  const __m256 yz = _mm256_shuffle_ps(m03, m14, _MM_SHUFFLE(1, 0, 2, 1));
  x = _mm256_shuffle_ps(m03, xy, _MM_SHUFFLE(2, 0, 3, 0));
  y = _mm256_shuffle_ps(yz, xy, _MM_SHUFFLE(3, 1, 2, 0));
  z = _mm256_shuffle_ps(yz, m25, _MM_SHUFFLE(3, 0, 3, 1));
}
#endif

}  // namespace canopy_ao
