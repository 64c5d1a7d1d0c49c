// Canopy AO — ray-traced AO reference with Embree 3 or 4 (see raytrace.h for the contract).
#include "canopy_ao/raytrace.h"
#include "canopy_ao/stage_clock.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <numeric>
#include <type_traits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>

#include "canopy_ao/parallel.h"
#include "embree_compat.h"

namespace canopy_ao {
namespace {

constexpr float kTwoPi = 6.28318530717958647692f;
// Rays per embree::occluded call (a stream on Embree 3, 8-wide packets on Embree 4): Embree 3's
// streams are fastest from ~64 rays (docs/DESIGN.md, 'Facts measured in Blender'). A batch is
// flushed once it holds kMinStream rays and its last point is complete, so at 64 samples a
// batch is one point's rays (one origin).
// Measured on Embree 3: as fast as 256-ray streams mixing four points (within the ±5% noise
// here), and as fast as a bare per-point rtcOccluded1M loop.
constexpr std::size_t kStream = 256;
constexpr std::size_t kMinStream = 64;
// Points per parallel block are chosen so a block holds about this many rays.
constexpr std::size_t kRaysPerBlock = 4096;
/// Per-corner rays of one vertex stop here (RayTraceOptions::per_corner; the samples cap of the
/// bindings, 2^16).
constexpr std::int64_t kMaxRaysPerVertex = 1 << 16;

// === Embree error plumbing
// Embree calls this from whichever thread hit the error; the first message is kept until the
// caller checks (libigl only printed it; here it reaches the caller as canopy_ao::Error).
struct ErrorRecord {
  std::mutex mutex;
  RTCError code = RTC_ERROR_NONE;
  std::string message;
};

void record_error(void* user, RTCError code, const char* str) {
  auto* rec = static_cast<ErrorRecord*>(user);
  std::lock_guard<std::mutex> lock(rec->mutex);
  if (rec->code == RTC_ERROR_NONE) {
    rec->code = code;
    rec->message = str ? str : "";
  }
}

const char* error_name(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "no error";
    case RTC_ERROR_UNKNOWN: return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
    default: break;  // Embree 4 adds codes (e.g. missing GPU support)
  }
  return "unrecognised error";
}

struct DeviceDeleter {
  void operator()(RTCDevice d) const { rtcReleaseDevice(d); }
};
struct SceneDeleter {
  void operator()(RTCScene s) const { rtcReleaseScene(s); }
};
using DevicePtr = std::unique_ptr<RTCDeviceTy, DeviceDeleter>;
using ScenePtr = std::unique_ptr<RTCSceneTy, SceneDeleter>;

// === Sampling
// splitmix64's finaliser (Steele et al., "Fast splittable pseudorandom number generators",
// OOPSLA 2014): a bijective 64-bit mix, good enough to decorrelate neighbouring point indices.
inline std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// The Cranley–Patterson shift of point `index`: two numbers in [0, 1).
inline void point_shift(std::size_t index, std::uint32_t seed, float* du, float* dv) {
  const std::uint64_t h =
      mix64(static_cast<std::uint64_t>(index) + mix64(0x9e3779b97f4a7c15ULL ^ seed));
  constexpr float k24 = 1.0f / 16777216.0f;
  *du = static_cast<float>(h >> 40) * k24;
  *dv = static_cast<float>((h >> 8) & 0xffffffu) * k24;
}

/// The shared stratified set: a Fibonacci lattice u_i = (i + ½)/N, v_i = frac(i/φ). The azimuth
/// is kept as (cos, sin) so a point's shift in v becomes one 2-D rotation, not a sincos per ray.
struct SampleSet {
  std::vector<float> u, cos_phi, sin_phi;
  explicit SampleSet(int n) : u(n), cos_phi(n), sin_phi(n) {
    const double inv_golden = 0.6180339887498948482;
    for (int i = 0; i < n; ++i) {
      u[i] = static_cast<float>((i + 0.5) / n);
      const double v = std::fmod(i * inv_golden, 1.0);
      cos_phi[i] = static_cast<float>(std::cos(2.0 * 3.14159265358979323846 * v));
      sin_phi[i] = static_cast<float>(std::sin(2.0 * 3.14159265358979323846 * v));
    }
  }
};

// --- Owen-scrambled Sobol' points (Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4),
// 2020): the first two Sobol' dimensions, shuffled and scrambled by a nested-uniform hash per
// point. Any prefix of 2^k points is a (0, k, 2)-net (stratified in every elementary interval),
// and any prefix stays well spread, whatever N.
inline std::uint32_t reverse_bits(std::uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

/// Burley's improved Laine–Karras hash: each bit flips depending only on the bits below it.
inline std::uint32_t laine_karras(std::uint32_t x, std::uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}

/// Owen scrambling of a 32-bit fixed-point number in [0, 1): bits from the most significant.
inline std::uint32_t owen_scramble(std::uint32_t x, std::uint32_t seed) {
  return reverse_bits(laine_karras(reverse_bits(x), seed));
}

/// Sobol' dimension 2 (dimension 1 is reverse_bits: van der Corput), 32-bit fixed point.
inline std::uint32_t sobol2(std::uint32_t i) {
  std::uint32_t r = 0;
  for (std::uint32_t v = 1u << 31; i; i >>= 1, v ^= v >> 1) {
    if (i & 1u) r ^= v;
  }
  return r;
}

/// One point's `n` cosine-weighted directions in its tangent frame (x, y on the unit disk, z =
/// height: Malley's method, u ∈ [0,1) → radius sqrt(u), height sqrt(1 − u)), from (point
/// index, seed) alone.
void point_directions(Sampling sampling, const SampleSet& set, std::size_t index,
                      std::uint32_t seed, int n, float* xs, float* ys, float* zs) {
  const std::uint64_t h =
      mix64(static_cast<std::uint64_t>(index) + mix64(0x9e3779b97f4a7c15ULL ^ seed));
  constexpr float k24 = 1.0f / 16777216.0f;
  if (sampling == Sampling::kLattice) {
    // The shared Fibonacci lattice, Cranley–Patterson-rotated by (du, dv): the shift in v is
    // one 2-D rotation of the stored (cos, sin), not a sincos per ray.
    float du, dv;
    point_shift(index, seed, &du, &dv);
    const float cr = std::cos(kTwoPi * dv), sr = std::sin(kTwoPi * dv);
    for (int s = 0; s < n; ++s) {
      float u = set.u[s] + du;
      u -= u >= 1.0f ? 1.0f : 0.0f;
      const float r = std::sqrt(u);
      zs[s] = std::sqrt(std::max(0.0f, 1.0f - u));
      xs[s] = r * (set.cos_phi[s] * cr - set.sin_phi[s] * sr);  // r cos(φ_s + 2π dv)
      ys[s] = r * (set.sin_phi[s] * cr + set.cos_phi[s] * sr);
    }
    return;
  }
  const auto shuffle = static_cast<std::uint32_t>(h), s0 = static_cast<std::uint32_t>(h >> 32);
  const auto s1 = static_cast<std::uint32_t>(mix64(h) >> 32);
  for (int s = 0; s < n; ++s) {
    float u, v;
    if (sampling == Sampling::kSobol) {
      const std::uint32_t i = owen_scramble(static_cast<std::uint32_t>(s), shuffle);
      u = static_cast<float>(owen_scramble(reverse_bits(i), s0) >> 8) * k24;
      v = static_cast<float>(owen_scramble(sobol2(i), s1) >> 8) * k24;
    } else {  // independent: a counter-based hash of (point, sample)
      const std::uint64_t r = mix64(h + 0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(s + 1));
      u = static_cast<float>(r >> 40) * k24;
      v = static_cast<float>((r >> 8) & 0xffffffu) * k24;
    }
    const float r = std::sqrt(u);
    xs[s] = r * std::cos(kTwoPi * v);
    ys[s] = r * std::sin(kTwoPi * v);
    zs[s] = std::sqrt(std::max(0.0f, 1.0f - u));
  }
}

/// Branchless orthonormal basis around unit n (Duff et al., JCGT 6(1) 2017, Listing 3).
inline void onb(Vec3 n, Vec3* t, Vec3* b) {
  const float sign = std::copysign(1.0f, n.z);
  const float a = -1.0f / (sign + n.z);
  const float c = n.x * n.y * a;
  *t = {1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x};
  *b = {c, sign + n.y * n.y * a, -n.y};
}

// === Opacity
/// A tracer's opacity (raytrace.h, "Opacity"), copied from Opacity at construction.
struct AlphaData {
  std::vector<std::int32_t> materials;  // M: index into the per-material arrays, −1 = opaque
  std::vector<float> uvs;               // 6M corner (u, v), or empty
  std::vector<float> constant;          // per material: the alpha when it has no texture
  std::vector<std::vector<float>> textures;  // per material: height × width alphas, or empty
  std::vector<int> width, height;
  std::vector<AlphaMaterial> post;  // per material: srgb, scale, offset (AlphaMaterial)
  // The geometry id of the reversed winding (a device culling back faces: raytrace.cpp's
  // two_sided_indices gives triangle (a, c, b) there), else none.
  unsigned flipped_geometry = ~0u;

  /// The alpha of triangle `prim` at Embree's barycentrics (bu, bv) on geometry `geom`.
  float alpha(unsigned prim, unsigned geom, float bu, float bv) const {
    const std::int32_t mat = materials[prim];
    if (mat < 0) return 1.0f;
    const std::vector<float>& tex = textures[static_cast<std::size_t>(mat)];
    if (tex.empty()) return constant[static_cast<std::size_t>(mat)];
    if (geom == flipped_geometry) std::swap(bu, bv);
    float u = 0.0f, v = 0.0f;
    if (!uvs.empty()) {
      const float* c = uvs.data() + 6 * static_cast<std::size_t>(prim);
      const float w0 = 1.0f - bu - bv;
      u = w0 * c[0] + bu * c[2] + bv * c[4];
      v = w0 * c[1] + bu * c[3] + bv * c[5];
    }
    const int w = width[static_cast<std::size_t>(mat)], h = height[static_cast<std::size_t>(mat)];
    const AlphaMaterial& p = post[static_cast<std::size_t>(mat)];
    const auto wrap = [](double i, int n) {  // Repeat extension
      const double r = std::fmod(i, static_cast<double>(n));
      return static_cast<std::size_t>(r < 0 ? r + n : r);
    };
    const std::size_t W = static_cast<std::size_t>(w);
    float t;
    if (p.nearest) {  // Closest: the texel holding the UV
      t = tex[wrap(std::floor(static_cast<double>(v) * h), h) * W +
              wrap(std::floor(static_cast<double>(u) * w), w)];
    } else {  // Linear: texel centres at (i + ½) / size
      const double x = static_cast<double>(u) * w - 0.5, y = static_cast<double>(v) * h - 0.5;
      const double fx = std::floor(x), fy = std::floor(y);
      const std::size_t x0 = wrap(fx, w), x1 = wrap(fx + 1, w), y0 = wrap(fy, h),
                        y1 = wrap(fy + 1, h);
      const float tx = static_cast<float>(x - fx), ty = static_cast<float>(y - fy);
      const float a0 = tex[y0 * W + x0] + (tex[y0 * W + x1] - tex[y0 * W + x0]) * tx;
      const float a1 = tex[y1 * W + x0] + (tex[y1 * W + x1] - tex[y1 * W + x0]) * tx;
      t = a0 + (a1 - a0) * ty;
    }
    if (p.srgb) {  // Cycles' color_srgb_to_linear
      t = t < 0.04045f ? std::max(t, 0.0f) * (1.0f / 12.92f)
                       : std::pow((t + 0.055f) * (1.0f / 1.055f), 2.4f);
    }
    return p.offset + p.scale * t;
  }
};

inline std::uint64_t float_bits(float a, float b) {
  std::uint32_t x, y;
  std::memcpy(&x, &a, 4);
  std::memcpy(&y, &b, 4);
  return (static_cast<std::uint64_t>(y) << 32) | x;
}

/// Whether hit k (on triangle prim, alpha a) stops its ray: always at a ≥ 1, never at a ≤ 0,
/// else when a hash of the ray (origin, direction) and the triangle, in [0, 1), is below a
/// (raytrace.h, "Opacity"): the ray's own data, so any thread count gives the same answer.
inline bool stops(const RTCFilterFunctionNArguments* args, unsigned k, unsigned prim, float a) {
  if (a >= 1.0f) return true;
  if (!(a > 0.0f)) return false;
  const unsigned N = args->N;
  RTCRayN* ray = args->ray;
  std::uint64_t h = mix64(float_bits(RTCRayN_org_x(ray, N, k), RTCRayN_org_y(ray, N, k)));
  h = mix64(h ^ float_bits(RTCRayN_org_z(ray, N, k), RTCRayN_dir_x(ray, N, k)));
  h = mix64(h ^ float_bits(RTCRayN_dir_y(ray, N, k), RTCRayN_dir_z(ray, N, k)));
  h = mix64(h ^ (0x9e3779b97f4a7c15ULL * (static_cast<std::uint64_t>(prim) + 1)));
  return static_cast<double>(h >> 11) * 0x1.0p-53 < static_cast<double>(a);
}

// === Own primitives
/// What a query hands to the filter: Embree passes filters a pointer to `base`, the first
/// member, so the filter can cast it back (standard layout).
struct TraceContext {
  embree::QueryContext base;
  const std::int32_t* own_vertex = nullptr;    // per query point (ray id), −1 = none
  const std::int32_t* own_triangle = nullptr;  // per query point (ray id), −1 = none
  const std::uint32_t* indices = nullptr;      // 3M: the tracer's triangles
  // When set, ray ids are slots of the current batch instead of query points, and ray_skip[slot]
  // is the one triangle that ray skips (−1 = none): Cycles' bake point (raytrace.h, "Origins").
  const std::int32_t* ray_skip = nullptr;
  const AlphaData* alpha = nullptr;  // the tracer's opacity, or null: every triangle opaque
};
static_assert(std::is_standard_layout<TraceContext>::value, "cast from the Embree context");

/// Occlusion filter on every triangle geometry: rejects a hit on the ray's own receiver's
/// triangles (ray id = query point), so traversal goes on past them. O(1) per hit: a triangle is
/// a vertex's own when one of its three indices is that vertex.
void skip_own(const RTCFilterFunctionNArguments* args) {
  const auto* c = reinterpret_cast<const TraceContext*>(args->context);
  if (c->ray_skip) {
    for (unsigned k = 0; k < args->N; ++k) {
      if (args->valid[k] == 0) continue;
      const unsigned slot = RTCRayN_id(args->ray, args->N, k);
      const unsigned prim = RTCHitN_primID(args->hit, args->N, k);
      if (c->ray_skip[slot] == static_cast<std::int32_t>(prim)) args->valid[k] = 0;
    }
    return;
  }
  if (c->own_vertex == nullptr && c->own_triangle == nullptr) return;
  for (unsigned k = 0; k < args->N; ++k) {
    if (args->valid[k] == 0) continue;
    const unsigned point = RTCRayN_id(args->ray, args->N, k);
    const unsigned prim = RTCHitN_primID(args->hit, args->N, k);
    if (c->own_triangle && c->own_triangle[point] == static_cast<std::int32_t>(prim)) {
      args->valid[k] = 0;
      continue;
    }
    if (c->own_vertex && c->own_vertex[point] >= 0) {
      const auto v = static_cast<std::uint32_t>(c->own_vertex[point]);
      const std::uint32_t* t = c->indices + 3 * static_cast<std::size_t>(prim);
      if (t[0] == v || t[1] == v || t[2] == v) args->valid[k] = 0;
    }
  }
}

/// The occlusion filter on the tracer's own triangles: skip_own, then a hit on a surface that
/// is not opaque lets its ray through as raytrace.h's "Opacity" says.
void skip_own_primitives(const RTCFilterFunctionNArguments* args) {
  skip_own(args);
  const auto* c = reinterpret_cast<const TraceContext*>(args->context);
  if (c->alpha == nullptr) return;
  for (unsigned k = 0; k < args->N; ++k) {
    if (args->valid[k] == 0) continue;
    const unsigned prim = RTCHitN_primID(args->hit, args->N, k);
    const float a = c->alpha->alpha(prim, RTCHitN_geomID(args->hit, args->N, k),
                                    RTCHitN_u(args->hit, args->N, k),
                                    RTCHitN_v(args->hit, args->N, k));
    if (!stops(args, k, prim, a)) args->valid[k] = 0;
  }
}

/// The start of a receiver lying on its own triangle: x moved towards `target` (that
/// triangle's centroid) by 1e-3 of the way, at least `precision` (float spacing of the scene's
/// coordinates), at most half the way. x itself when target = x.
inline Vec3 own_surface_origin(Vec3 x, Vec3 target, float precision) {
  const Vec3 d = target - x;
  const float len = length(d);
  if (!(len > 0.0f)) return x;
  const float step = std::min(0.5f * len, std::max(1e-3f * len, precision));
  return x + d * (step / len);
}

/// raw normalised, or (0, 0, 0) when it is zero: scaled by its largest component first, so
/// tiny (1e-25) normals do not underflow to zero.
inline Vec3 unit_or_zero(Vec3 raw) {
  const float big = std::max(std::fabs(raw.x), std::max(std::fabs(raw.y), std::fabs(raw.z)));
  return big > 0.0f ? normalize(raw / big) : Vec3{0.0f, 0.0f, 0.0f};
}

/// The barycentric weights (of V[1], V[2]) of x's projection onto triangle V's plane, unclamped;
/// false for a degenerate triangle.
inline bool barycentric(const Vec3 V[3], Vec3 x, float* v, float* w) {
  const Vec3 e1 = V[1] - V[0], e2 = V[2] - V[0], vp = x - V[0];
  const float d11 = dot(e1, e1), d12 = dot(e1, e2), d22 = dot(e2, e2);
  const float denom = d11 * d22 - d12 * d12;
  if (!(denom > 0.0f)) return false;
  const float dp1 = dot(vp, e1), dp2 = dot(vp, e2);
  *v = (d22 * dp1 - d12 * dp2) / denom;
  *w = (d11 * dp2 - d12 * dp1) / denom;
  return true;
}

/// Cycles' bake_offset_towards_center (kernel integrator/init_from_bake.h, Blender 3.x-5.x),
/// float for float: vertex `slot` of triangle V moved towards the centroid by min(distance,
/// reach), projected back onto the triangle's plane for its barycentric weights w (of V[0],
/// V[1], V[2]), clamped to [1e-5, 1 - 1e-5] and V[2]'s weight what the others leave. Cycles'
/// CPU kernels are compiled with FMA contraction: the move and each 2 x 2 determinant are
/// fused. Reproduced: the bake points Cycles shades (its Position, baked per face corner) on
/// the Douglas fir's 57k branch triangles agree with these within 6e-6 at all but 7 of their
/// 171k corners, and at all but 3 of the 6,558 corners of its 2,186 triangles whose last two
/// vertices coincide, where the same arithmetic without fusing misses 64-100 % of them, and
/// the move's exact barycentrics 14k of the 171k (by up to 4 cm, on slivers). Every traced
/// corner of a vertex starts here (RayTracer::Impl::corners). std::fma makes the fused
/// operations the same on any compiler; nothing else here may be contracted (CMakeLists.txt
/// compiles this file with -ffp-contract=off).
void cycles_bake_offset(const Vec3 V[3], int slot, float reach, float w[3]) {
  const auto divide = [](Vec3 a, float s) { return Vec3{a.x / s, a.y / s, a.z / s}; };
  const Vec3 P = V[slot];
  const Vec3 to = divide(V[0] + V[1] + V[2], 3.0f) - P;  // a division, as Cycles' float3
  const float len = std::sqrt(dot(to, to));
  const Vec3 dir = divide(to, len);
  const float step = std::min(len, reach);
  const Vec3 moved = len > 0.0f ? Vec3{std::fma(dir.x, step, P.x), std::fma(dir.y, step, P.y),
                                       std::fma(dir.z, step, P.z)}
                                : P;
  const Vec3 v1 = V[1] - V[0], v2 = V[2] - V[0], vp = moved - V[0];
  const float d11 = dot(v1, v1), d12 = dot(v1, v2), d22 = dot(v2, v2);
  const float dp1 = dot(vp, v1), dp2 = dot(vp, v2);
  const float denom = std::fma(d11, d22, -(d12 * d12));
  if (denom == 0.0f) {  // Cycles' (u, v) = (0, 0): the third vertex
    w[0] = w[1] = 0.0f;
    w[2] = 1.0f;
    return;
  }
  const float ov = std::clamp(std::fma(d22, dp1, -(d12 * dp2)) / denom, 1e-5f, 1.0f - 1e-5f);
  const float ow = std::clamp(std::fma(d11, dp2, -(d12 * dp1)) / denom, 1e-5f, 1.0f - 1e-5f);
  w[0] = std::clamp(1.0f - ov - ow, 1e-5f, 1.0f - 1e-5f);
  w[1] = ov;
  w[2] = 1.0f - w[0] - w[1];
}

/// Cycles' face normal on an FMA machine, unnormalised: each component one fused
/// multiply-subtract, which for two equal edges leaves each product's rounding error.
inline Vec3 cycles_cross(Vec3 a, Vec3 b) {
  return Vec3{std::fma(a.y, b.z, -(a.z * b.y)), std::fma(a.z, b.x, -(a.x * b.z)),
              std::fma(a.x, b.y, -(a.y * b.x))};
}

/// Cycles' default shadow-terminator geometry offset (Object > Shading): rays within this
/// cosine of grazing their face start lifted onto the smooth surface (raytrace.h, "Origins").
constexpr float kTerminatorCutoff = 0.1f;

/// One corner of a vertex receiver started at Cycles' bake point (raytrace.h, "Origins").
struct Corner {
  Vec3 start;         // the vertex moved towards the centroid (bake_offset_towards_center)
  Vec3 t, b, n;       // frame around the smooth normal interpolated at `start`
  Vec3 ng;            // the face normal, on n's side
  Vec3 lift;          // Cycles' shadow_ray_smooth_surface_offset at `start` (full amount)
  std::int32_t tri;   // the corner's triangle, the one its rays skip
  Vec3 V[3];          // its vertices, for Cycles' self-intersection test (cycles_hits_self)
  bool open = false;  // Cycles bakes it with a NaN face normal: every ray counts as unblocked
};

/// Cycles' ray_offset (kernel/bvh/util.h, Blender 3.2-5.x: Wächter and Binder, "A Fast and
/// Robust Method for Avoiding Self-Intersection", Ray Tracing Gems ch. 6): each coordinate
/// moved int(256 × Ng) float spacings along the face normal Ng (by 2^-16 × Ng within 1/32 of
/// the origin) — 256 spacings is 0.5 mm at 20 units from the origin.
inline Vec3 cycles_ray_offset(Vec3 P, Vec3 ng) {
  const auto one = [](float p, float n) {
    if (std::fabs(p) < 1.0f / 32.0f) return p + (1.0f / 65536.0f) * n;
    const std::int32_t of = static_cast<std::int32_t>(256.0f * n);
    std::int32_t bits;
    std::memcpy(&bits, &p, sizeof bits);
    bits += p < 0.0f ? -of : of;
    float out;
    std::memcpy(&out, &bits, sizeof out);
    return out;
  };
  return Vec3{one(P.x, ng.x), one(P.y, ng.y), one(P.z, ng.z)};
}

/// Cycles' ray_triangle_intersect_self (util/math_intersect.h), its SSE madd and msub fused as
/// on an FMA machine: whether the ray from P along D passes strictly inside triangle V by
/// Cycles' edge tests. Where it does not (a start within rounding of an edge), Cycles'
/// integrate_surface_ray_offset moves the ray's origin by ray_offset (raytrace.h, "Origins").
inline bool cycles_hits_self(Vec3 P, Vec3 D, const Vec3 V[3]) {
  const Vec3 v0 = V[0] - P, v1 = V[1] - P, v2 = V[2] - P;
  const Vec3 e0 = v2 - v0, e1 = v0 - v1, e2 = v1 - v2;
  const auto dt = [](Vec3 a, Vec3 b) { return std::fma(a.x, b.x, std::fma(a.y, b.y, a.z * b.z)); };
  const float U = dt(cycles_cross(v2 + v0, e0), D), Vv = dt(cycles_cross(v0 + v1, e1), D),
              W = dt(cycles_cross(v1 + v2, e2), D);
  const float eps = FLT_EPSILON * std::fabs(U + Vv + W);
  const float lo = std::min(U, std::min(Vv, W)), hi = std::max(U, std::max(Vv, W));
  return lo >= eps || hi <= -eps;
}

/// Where Blender's vertex bake evaluates one face corner of a vertex (raytrace.h, "Origins"):
/// the tracer's triangle `tri` at its vertex `slot`, which is not always the corner's own
/// vertex (see RayTracer::Impl::build_bake_corners).
struct BakeCorner {
  std::uint32_t tri;
  std::uint8_t slot;
  bool open;  // tri has a vertex on its first one (an edge from it of length 0): NaN normal
  bool residue = false;  // tri's last two vertices coincide: Cycles' face normal is the
                         // rounding residue of its fused cross product
};

/// Cycles' shadow_ray_smooth_surface_offset: the point lifted by h along the interpolated
/// (unnormalised) normal onto a parabolic patch through the vertex normals, bounded by the
/// local linear envelope. V, N: the triangle's vertices and unit vertex normals; w: the
/// barycentric weights of the point (of V[0], V[1], V[2]); ng: the face normal as shaded.
Vec3 smooth_surface_offset(const Vec3 V[3], const Vec3 N[3], const float w[3], Vec3 ng) {
  const float u = w[0], v = w[1], ww = w[2];
  const Vec3 P = V[0] * u + V[1] * v + V[2] * ww;
  const Vec3 n = N[0] * u + N[1] * v + N[2] * ww;
  const float a = dot(N[2] - N[0], V[0] - V[2]);
  const float b = dot(N[2] - N[1], V[1] - V[2]);
  const float c = dot(N[1] - N[0], V[1] - V[0]);
  float h = a * u * (u - 1) + (a + b + c) * u * v + b * v * (v - 1);
  if (dot(n, ng) > 0) {
    float h0 = std::max(std::max(dot(V[1] - V[0], N[0]), dot(V[2] - V[0], N[0])), 0.0f);
    float h1 = std::max(std::max(dot(V[0] - V[1], N[1]), dot(V[2] - V[1], N[1])), 0.0f);
    float h2 = std::max(std::max(dot(V[0] - V[2], N[2]), dot(V[1] - V[2], N[2])), 0.0f);
    h0 = std::max(dot(V[0] - P, N[0]) + h0, 0.0f);
    h1 = std::max(dot(V[1] - P, N[1]) + h1, 0.0f);
    h2 = std::max(dot(V[2] - P, N[2]) + h2, 0.0f);
    h = std::max(std::min(std::min(h0, h1), h2), h * 0.5f);
  } else {
    float h0 = std::max(std::max(dot(V[0] - V[1], N[0]), dot(V[0] - V[2], N[0])), 0.0f);
    float h1 = std::max(std::max(dot(V[1] - V[0], N[1]), dot(V[1] - V[2], N[1])), 0.0f);
    float h2 = std::max(std::max(dot(V[2] - V[0], N[2]), dot(V[2] - V[1], N[2])), 0.0f);
    h0 = std::max(dot(P - V[0], N[0]) + h0, 0.0f);
    h1 = std::max(dot(P - V[1], N[1]) + h1, 0.0f);
    h2 = std::max(dot(P - V[2], N[2]) + h2, 0.0f);
    h = std::min(-std::min(std::min(h0, h1), h2), h * 0.5f);
  }
  return n * h;
}

void check_ids(const std::int32_t* ids, std::size_t n, std::size_t limit, const char* name,
               const char* what) {
  if (ids == nullptr) return;
  for (std::size_t i = 0; i < n; ++i) {
    if (ids[i] < -1 || (ids[i] >= 0 && static_cast<std::size_t>(ids[i]) >= limit)) {
      std::ostringstream s;
      s << name << "[" << i << "] = " << ids[i] << " is neither -1 (none) nor a " << what
        << " index in [0, " << limit << ")";
      throw std::invalid_argument(s.str());
    }
  }
}

void check_points(PointsView p, const char* name) {
  if (p.size > 0 && p.data == nullptr) {
    throw std::invalid_argument(std::string(name) + " is null");
  }
  for (std::size_t i = 0; i < 3 * p.size; ++i) {
    if (!std::isfinite(p.data[i])) {
      std::ostringstream s;
      s << name << " has a non-finite value (NaN or inf) at row " << i / 3;
      throw std::invalid_argument(s.str());
    }
  }
}

/// Attaches triangles (shared buffers: they must outlive the scene) to `scene`; `filter` may be
/// null. Returns Embree's error state through the caller's check().
void attach_triangles(RTCDevice device, RTCScene scene, const float* vertices,
                      std::size_t vertex_count, const std::uint32_t* indices,
                      std::size_t triangle_count, RTCFilterFunctionN filter) {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  if (geom == nullptr) return;  // the error callback has the reason
  rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices, 0,
                             3 * sizeof(float), vertex_count);
  rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices, 0,
                             3 * sizeof(std::uint32_t), triangle_count);
  if (filter) rtcSetGeometryOccludedFilterFunction(geom, filter);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);  // the scene holds its own reference
}

/// The indices of `triangles` (validated), then, when the device culls back faces, each
/// triangle again with the opposite winding (two-sided occluders: Debian's Embree does not
/// cull; a build that does gets both windings). Returns the triangle count per winding.
std::size_t two_sided_indices(const std::int32_t* triangles, std::size_t count, bool culls,
                              std::vector<std::uint32_t>* out) {
  out->resize((culls ? 6 : 3) * count);
  for (std::size_t i = 0; i < 3 * count; ++i) (*out)[i] = static_cast<std::uint32_t>(triangles[i]);
  if (culls) {
    std::uint32_t* flipped = out->data() + 3 * count;
    for (std::size_t j = 0; j < count; ++j) {
      flipped[3 * j] = (*out)[3 * j];
      flipped[3 * j + 1] = (*out)[3 * j + 2];
      flipped[3 * j + 2] = (*out)[3 * j + 1];
    }
  }
  return count;
}

void check_mesh(PointsView vertices, const std::int32_t* triangles, std::size_t triangle_count,
                const std::string& what) {
  check_points(vertices, (what + "vertices").c_str());
  if (triangle_count > 0 && triangles == nullptr) {
    throw std::invalid_argument(what + "triangles is null");
  }
  if (vertices.size > 0xffffffffu || triangle_count > 0x7fffffffu) {
    throw std::invalid_argument(what + "mesh too large for 32-bit indices");
  }
  for (std::size_t i = 0; i < 3 * triangle_count; ++i) {
    if (triangles[i] < 0 || static_cast<std::size_t>(triangles[i]) >= vertices.size) {
      std::ostringstream s;
      s << what << "triangles row " << i / 3 << " has vertex index " << triangles[i]
        << ", outside [0, " << vertices.size << ")";
      throw std::invalid_argument(s.str());
    }
  }
}

// === Bent normals (raytrace.h, "Bent normals")
/// Adds each unblocked ray's direction to its point's running sum (3 floats per point, indexed
/// by owner). Rays are summed in their sample order, so the sum is the same however the points
/// are split into blocks and streams.
void accumulate_open(const RTCRay* rays, const std::uint32_t* owner, std::size_t count,
                     float* sums) {
  for (std::size_t r = 0; r < count; ++r) {
    if (!(rays[r].tfar >= 0.0f)) continue;  // occluded: Embree set tfar to -inf
    float* s = sums + 3 * static_cast<std::size_t>(owner[r]);
    s[0] += rays[r].dir_x;
    s[1] += rays[r].dir_y;
    s[2] += rays[r].dir_z;
  }
}

/// bent[3i..3i+3) for points [begin, end): the normalised sum (sums indexed from begin; null =
/// no ray was blocked or traced, the normal stands), the unit normal where every ray was
/// blocked, (0, 0, 0) for a zero normal.
void finish_bent(PointsView normals, std::size_t begin, std::size_t end, const float* sums,
                 float* bent) {
  for (std::size_t i = begin; i < end; ++i) {
    Vec3 b = unit_or_zero(normals[i]);
    if (sums && length(b) > 0.0f) {
      const float* s = sums + 3 * (i - begin);
      const Vec3 v{s[0], s[1], s[2]};
      const float len = length(v);
      if (len > 0.0f) b = v / len;
    }
    bent[3 * i] = b.x;
    bent[3 * i + 1] = b.y;
    bent[3 * i + 2] = b.z;
  }
}

}  // namespace

// === Impl
struct RayTracer::Impl {
  /// A prototype's own scene, instanced by the main one (buffers first: they outlive it).
  struct Prototype {
    std::vector<float> vertices;  // 3V + 1 of padding
    std::vector<std::uint32_t> indices;
    ScenePtr scene;
  };

  // Declaration order is destruction order reversed: the scene goes first (it holds the
  // instances), then the prototypes' scenes, then the device, all before the buffers Embree
  // shares and the error record its callback writes to. (A prototype scene released after its
  // device corrupted the heap on Embree 4.4.)
  std::unique_ptr<ErrorRecord> errors = std::make_unique<ErrorRecord>();
  std::vector<float> vertices;       // 3V floats + 1 of padding (Embree reads 16 bytes)
  std::vector<std::uint32_t> indices;  // 3M (6M when the device culls back faces)
  std::size_t instance_count = 0;
  // The triangles using each vertex (CSR): vertex v's are tris_of[first_tri[v] .. first_tri[v+1]).
  std::vector<std::uint32_t> first_tri, tris_of;
  std::size_t vertex_count = 0;
  std::vector<float> vertex_normals;  // 3V unit (or zero) normals, or empty: no bake point
  std::vector<float> corner_normals;  // 9M unit (or zero) corner normals, or empty: vertices'
  std::vector<std::int32_t> polygons;  // M polygon ids (a quad's two triangles share one), or empty
  std::size_t triangle_count = 0;
  // Each vertex's corners where Cycles' bake evaluates them (CSR, vertex v's are
  // bake_corners[corner_first[v] .. corner_first[v+1])), built with the vertex normals; both
  // empty without them (no bake point: one start per receiver).
  std::vector<std::uint32_t> corner_first;
  std::vector<BakeCorner> bake_corners;
  float auto_offset = 0;
  float precision = 0;  // float spacing of the coordinates: 1e-6 × the largest |coordinate|
  DevicePtr device;
  std::vector<std::unique_ptr<Prototype>> prototypes;  // instanced meshes (occluders only)
  ScenePtr scene;
  std::unique_ptr<AlphaData> alpha;  // the triangles' opacity, or null: all opaque

  Vec3 vertex(std::uint32_t i) const {
    return {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
  }
  Vec3 centroid(std::uint32_t tri) const {
    const std::uint32_t* t = indices.data() + 3 * static_cast<std::size_t>(tri);
    return (vertex(t[0]) + vertex(t[1]) + vertex(t[2])) / 3.0f;
  }
  /// Where vertex v's rays aim their start (see own_surface_origin): the centroid of the
  /// triangle using v whose plane faces unit normal n most squarely (the first such on ties;
  /// zero-area triangles never), so the start stays on the surface, not inside the solid a
  /// convex corner bounds. v itself when no triangle with area uses it.
  Vec3 vertex_target(std::uint32_t v, Vec3 n) const {
    float best = -1.0f;
    std::uint32_t pick = 0;
    for (std::uint32_t k = first_tri[v]; k < first_tri[v + 1]; ++k) {
      const std::uint32_t* t = indices.data() + 3 * static_cast<std::size_t>(tris_of[k]);
      const Vec3 a = vertex(t[0]);
      const Vec3 c = cross(vertex(t[1]) - a, vertex(t[2]) - a);
      const float len = length(c);
      if (!(len > 0.0f)) continue;
      const float facing = std::fabs(dot(c, n)) / len;
      if (facing > best) {
        best = facing;
        pick = tris_of[k];
      }
    }
    return best >= 0.0f ? centroid(pick) : vertex(v);
  }

  /// Cycles' bake offset at P: 1e-4 × max(1, largest |coordinate|) (bake_offset_towards_center).
  static float bake_reach(Vec3 P) {
    return 1e-4f *
           std::max(1.0f, std::max(std::fabs(P.x), std::max(std::fabs(P.y), std::fabs(P.z))));
  }

  bool has_area(std::uint32_t tri) const {
    const std::uint32_t* t = indices.data() + 3 * static_cast<std::size_t>(tri);
    const Vec3 a = vertex(t[0]);
    return length(cross(vertex(t[1]) - a, vertex(t[2]) - a)) > 0.0f;
  }

  /// The bake corners of every vertex (corner_first, bake_corners; raytrace.h, "Origins").
  /// Blender bakes a POINT-domain colour per face corner, each on the first triangle of its
  /// face that holds it, in the face's triangulation as the bake computes it
  /// (bake_targets_populate_pixels_color_attributes: corner_tris_calc without face normals,
  /// Blender 3.x–5.x), at that triangle's vertex slot j; Cycles then evaluates triangle i of
  /// *its own* triangle list (the mesh's cached triangulation, which the tracer is given) at
  /// slot j. The two triangulations of a quad differ where Blender's quad-flip test differs
  /// with and without the face normal — on a quad with two coincident corners (a branch tip
  /// Sapling collapses) — and then one corner is baked at the quad's fourth vertex instead of
  /// its own. A triangle whose first vertex coincides with another has a zero edge from it:
  /// Cycles' face normal there is NaN and so is every ray's direction, which Embree never
  /// stops (the corner reads 1.0). Other triangles of zero area give no corner.
  void build_bake_corners(std::size_t nverts) {
    struct Entry {
      std::uint32_t v, tri;
      std::uint8_t slot;
    };
    std::vector<Entry> entries;
    entries.reserve(3 * triangle_count);
    auto corner_of = [&](std::uint32_t v, std::uint32_t tri, std::uint8_t slot) {
      entries.push_back({v, tri, slot});
    };
    const std::uint32_t* ix = indices.data();
    if (polygons.empty()) {  // every triangle is a face
      for (std::uint32_t t = 0; t < triangle_count; ++t) {
        for (std::uint8_t j = 0; j < 3; ++j) corner_of(ix[3 * t + j], t, j);
      }
    } else {
      // The triangles of each face, in triangle order.
      std::vector<std::uint32_t> order(triangle_count);
      for (std::uint32_t t = 0; t < triangle_count; ++t) order[t] = t;
      std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
        return polygons[a] < polygons[b];
      });
      for (std::size_t s = 0; s < order.size();) {
        std::size_t e = s + 1;
        while (e < order.size() && polygons[order[e]] == polygons[order[s]]) ++e;
        const std::uint32_t* X = ix + 3 * static_cast<std::size_t>(order[s]);
        const std::uint32_t* Y = e - s == 2 ? ix + 3 * static_cast<std::size_t>(order[s + 1])
                                            : nullptr;
        std::uint32_t loops[4];
        bool quad = false;
        if (Y && X[0] == Y[0]) {  // split (0 1 2)(0 2 3)
          loops[0] = X[0], loops[1] = X[1], loops[2] = X[2], loops[3] = Y[2];
          quad = true;
        } else if (Y && X[1] == Y[0] && X[2] == Y[2]) {  // split (0 1 3)(1 2 3)
          loops[0] = X[0], loops[1] = X[1], loops[2] = Y[1], loops[3] = X[2];
          quad = true;
        }
        if (quad) {
          // Blender's is_quad_flip_v3_first_third_fast on the quad: the bake's split.
          const Vec3 p0 = vertex(loops[0]), d12 = vertex(loops[1]) - p0,
                     d13 = vertex(loops[2]) - p0, d14 = vertex(loops[3]) - p0;
          const bool flip = dot(cross(d12, d13), cross(d14, d13)) > 0.0f;
          static const std::uint8_t kSplit[2][2][3] = {{{0, 1, 2}, {0, 2, 3}},
                                                       {{0, 1, 3}, {1, 2, 3}}};
          bool seen[4] = {false, false, false, false};
          for (int k = 0; k < 2; ++k) {
            for (std::uint8_t j = 0; j < 3; ++j) {
              const std::uint8_t l = kSplit[flip][k][j];
              if (seen[l]) continue;
              seen[l] = true;
              corner_of(loops[l], order[s + static_cast<std::size_t>(k)], j);
            }
          }
        } else {  // a triangle or an n-gon: the first of its triangles holding the vertex
          for (std::size_t q = s; q < e; ++q) {
            const std::uint32_t t = order[q];
            for (std::uint8_t j = 0; j < 3; ++j) {
              bool dup = false;
              for (std::size_t r = s; r < q && !dup; ++r) {
                const std::uint32_t* u = ix + 3 * static_cast<std::size_t>(order[r]);
                dup = u[0] == ix[3 * t + j] || u[1] == ix[3 * t + j] || u[2] == ix[3 * t + j];
              }
              if (!dup) corner_of(ix[3 * t + j], t, j);
            }
          }
        }
        s = e;
      }
    }
    std::stable_sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
      return a.v != b.v ? a.v < b.v : a.tri < b.tri;
    });
    corner_first.assign(nverts + 1, 0);
    bake_corners.clear();
    bake_corners.reserve(entries.size());
    for (const Entry& en : entries) {
      const std::uint32_t* t = ix + 3 * static_cast<std::size_t>(en.tri);
      const Vec3 e1 = vertex(t[1]) - vertex(t[0]), e2 = vertex(t[2]) - vertex(t[0]);
      const bool nan_normal = (e1.x == 0.0f && e1.y == 0.0f && e1.z == 0.0f) ||
                              (e2.x == 0.0f && e2.y == 0.0f && e2.z == 0.0f);
      const bool residue = !nan_normal && !has_area(en.tri);
      // No residue at all (every product exact): Cycles' face normal is 0 / 0, NaN, as above.
      const bool open = nan_normal || (residue && !(length(cycles_cross(e1, e2)) > 0.0f));
      bake_corners.push_back({en.tri, en.slot, open, residue && !open});
      ++corner_first[en.v + 1];
    }
    for (std::size_t v = 0; v < nverts; ++v) corner_first[v + 1] += corner_first[v];
  }

  /// Vertex v's corner count as the cost model counts it: its bake corners, at least 1 (a
  /// vertex with none casts one set from its fallback start). Needs corner_first.
  std::uint32_t corner_total(std::size_t v) const {
    return std::max<std::uint32_t>(1, corner_first[v + 1] - corner_first[v]);
  }

  /// Vertex v's corners at Cycles' bake point (raytrace.h, "Origins"): one per bake corner,
  /// each started at the vertex its triangle's slot names; none when v has no bake corner.
  void corners(std::uint32_t v, std::vector<Corner>* out) const {
    out->clear();
    for (std::uint32_t k = corner_first[v]; k < corner_first[v + 1]; ++k) {
      const BakeCorner& bc = bake_corners[k];
      Corner cn;
      if (bc.open) {
        cn.open = true;
        cn.tri = static_cast<std::int32_t>(bc.tri);
        out->push_back(cn);
        continue;
      }
      const std::uint32_t tri = bc.tri;
      const std::uint32_t* t = indices.data() + 3 * static_cast<std::size_t>(tri);
      const Vec3 V[3] = {vertex(t[0]), vertex(t[1]), vertex(t[2])};
      const Vec3 P = V[bc.slot];
      const float reach = bake_reach(P);
      // Cycles' bake point: the vertex moved towards the centroid and projected back onto the
      // triangle in Cycles' float arithmetic. On a sliver (a twig segment 2.6 units by 0.02)
      // that projection cancels catastrophically and lands the start anywhere along it, often
      // within rounding of an edge — at the Douglas fir's twin rings back at the vertex, inside
      // the next branch piece — and on a residue corner's triangle anywhere at all. Cycles'
      // self-intersection test then offsets the rays from such a start (cycles_hits_self, in
      // RayTracer::ao), which is what makes it reproducible (docs/DESIGN.md, 'Rays against
      // Cycles' samples', "Slivers"). The face normal is Cycles' fused cross product: on a
      // residue corner its rounding residue, with the corner backfacing where that opposes
      // the smooth normal.
      float w[3];
      cycles_bake_offset(V, bc.slot, reach, w);
      const Vec3 ng = normalize(cycles_cross(V[1] - V[0], V[2] - V[0]));
      out->push_back(corner_at(tri, V, ng, w, nullptr, bc.residue));
    }
  }

  /// The Corner of a bake point with barycentric weights w on triangle tri (vertices V, unit
  /// face normal ng): the smooth normal interpolated there (or `normal` when given: a texel's
  /// own), the face normal on its side, and the terminator lift. backfacing: where the face
  /// normal opposes the smooth one, flip the smooth normal too, as Cycles shades a backfacing
  /// hit — a residue corner, whose face normal is a direction at random (raytrace.h,
  /// 'Origins'): its hemisphere then turns into the surface.
  Corner corner_at(std::uint32_t tri, const Vec3 V[3], Vec3 ng, const float w[3],
                   const Vec3* normal, bool backfacing = false) const {
    const std::uint32_t* t = indices.data() + 3 * static_cast<std::size_t>(tri);
    Vec3 N[3];
    for (int j = 0; j < 3; ++j) {
      // The corner's own normal where given (BakeShading::corner_normals), as Cycles shades it.
      const float* q = corner_normals.empty()
                           ? vertex_normals.data() + 3 * static_cast<std::size_t>(t[j])
                           : corner_normals.data() + 9 * static_cast<std::size_t>(tri) + 3 * j;
      N[j] = Vec3{q[0], q[1], q[2]};
      if (!(length(N[j]) > 0.0f)) N[j] = ng;  // a zero vertex normal: the face's
    }
    Vec3 n = normal ? *normal : N[0] * w[0] + N[1] * w[1] + N[2] * w[2];
    const float nl = length(n);
    n = nl > 0.0f ? n / nl : ng;
    // The face normal on the shading normal's side. (Where a vertex normal opposes its face,
    // which Blender's own normals never do, Cycles would bake the other hemisphere; the
    // receiver's normal is kept instead, but for a residue corner.)
    if (dot(ng, n) < 0.0f) {
      ng = -ng;
      if (backfacing) n = -n;
    }
    Corner cn;
    // Cycles' triangle_point_normal, u·v0 + v·v1 + t·v2 with both additions fused (its CPU
    // kernels contract them): a start on a face lying in another face's plane stays in it.
    const auto at = [&](float Vec3::*c) {
      return std::fma(w[2], V[2].*c, std::fma(w[1], V[1].*c, w[0] * (V[0].*c)));
    };
    cn.start = Vec3{at(&Vec3::x), at(&Vec3::y), at(&Vec3::z)};
    cn.n = n;
    onb(n, &cn.t, &cn.b);
    cn.ng = ng;
    cn.lift = smooth_surface_offset(V, N, w, ng);
    cn.tri = static_cast<std::int32_t>(tri);
    for (int j = 0; j < 3; ++j) cn.V[j] = V[j];
    return cn;
  }

  /// A texel's single corner: the point x on triangle tri with the texel's unit normal n.
  bool texel_corner(Vec3 x, std::uint32_t tri, Vec3 n, Corner* out) const {
    const std::uint32_t* t = indices.data() + 3 * static_cast<std::size_t>(tri);
    const Vec3 V[3] = {vertex(t[0]), vertex(t[1]), vertex(t[2])};
    const Vec3 c = cross(V[1] - V[0], V[2] - V[0]);
    const float area2 = length(c);
    float w[3];
    if (!(area2 > 0.0f) || !barycentric(V, x, &w[1], &w[2])) return false;
    w[1] = std::clamp(w[1], 0.0f, 1.0f);
    w[2] = std::clamp(w[2], 0.0f, 1.0f - w[1]);
    w[0] = 1.0f - w[1] - w[2];
    // A texel on its triangle's boundary (a conservative texel's closest point, on an edge
    // or a vertex such as a UV sphere's pole, in 3D within rounding of it) starts where the
    // faces meeting there stop rays at t = 0 whichever side of the edge the rounding put it:
    // inside, Cycles' edge test does not offset it (at a UV sphere's pole 6 % of the rays
    // stopped). Below Cycles' own barycentric floor (1e-5, as its bake clamps u and v) it
    // moves towards the centroid by Cycles' bake reach, as a vertex's corner does
    // (bake_offset_towards_center): inside, where only its own triangle is skipped.
    const bool on_boundary = !(std::min(w[0], std::min(w[1], w[2])) >= 1e-5f);
    if (on_boundary) {
      const Vec3 to = (V[0] + V[1] + V[2]) / 3.0f - x;
      const float len = length(to);
      const float f = len > 0.0f ? std::min(1.0f, bake_reach(x) / len) : 0.0f;
      for (float& wk : w) wk += (1.0f / 3.0f - wk) * f;
    }
    *out = corner_at(tri, V, c / area2, w, &n);
    if (!on_boundary) out->start = x;  // the texel itself (the weights only shape the lift)
    return true;
  }

  /// Throws canopy_ao::Error if Embree reported anything since the last check.
  void check(const char* what) const {
    RTCError code = device ? rtcGetDeviceError(device.get()) : rtcGetDeviceError(nullptr);
    std::string message;
    {
      std::lock_guard<std::mutex> lock(errors->mutex);
      if (errors->code != RTC_ERROR_NONE) {
        code = errors->code;
        message = std::move(errors->message);
        errors->code = RTC_ERROR_NONE;
        errors->message.clear();
      }
    }
    if (code == RTC_ERROR_NONE) return;
    std::ostringstream s;
    s << "Embree " << what << " failed: " << error_name(code);
    if (!message.empty()) s << " (" << message << ")";
    throw Error(s.str());
  }

};

// === Constructor
RayTracer::RayTracer(PointsView vertices, const std::int32_t* triangles,
                     std::size_t triangle_count, const RayTracerBuildOptions& build)
    : RayTracer(vertices, triangles, triangle_count, {}, {}, build) {}

RayTracer::RayTracer(PointsView vertices, const std::int32_t* triangles,
                     std::size_t triangle_count, const std::vector<Prototype>& prototypes,
                     const std::vector<Instance>& instances, const RayTracerBuildOptions& build)
    : RayTracer(vertices, triangles, triangle_count, BakeShading{}, prototypes, instances,
                build) {}

RayTracer::RayTracer(PointsView vertices, const std::int32_t* triangles,
                     std::size_t triangle_count, const BakeShading& shading,
                     const std::vector<Prototype>& prototypes,
                     const std::vector<Instance>& instances, const RayTracerBuildOptions& build)
    : RayTracer(vertices, triangles, triangle_count, shading, Opacity{}, prototypes, instances,
                build) {}

namespace {
/// The AlphaData of `opacity` over `triangle_count` triangles (validated), or null when every
/// triangle is opaque (then the tracer is the same as without it).
std::unique_ptr<AlphaData> alpha_data(const Opacity& opacity, std::size_t triangle_count) {
  if (opacity.materials == nullptr || triangle_count == 0) return nullptr;
  const std::size_t n = opacity.alphas.size();
  auto a = std::make_unique<AlphaData>();
  a->constant.resize(n);
  a->textures.resize(n);
  a->width.resize(n);
  a->height.resize(n);
  a->post.resize(n);
  std::vector<bool> clear(n, false);  // a material some ray may pass
  for (std::size_t k = 0; k < n; ++k) {
    const AlphaMaterial& in = opacity.alphas[k];
    const std::string what = "opacity material " + std::to_string(k) + ": ";
    if (in.texture != nullptr) {
      if (in.width < 1 || in.height < 1) {
        throw std::invalid_argument(what + "texture size must be positive, got " +
                                    std::to_string(in.width) + " x " + std::to_string(in.height));
      }
      const std::size_t count = static_cast<std::size_t>(in.width) * in.height;
      a->textures[k].assign(in.texture, in.texture + count);
      for (float x : a->textures[k]) {
        if (!std::isfinite(x)) throw std::invalid_argument(what + "non-finite texture alpha");
        clear[k] = clear[k] || x < 1.0f;
      }
      if (!std::isfinite(in.scale) || !std::isfinite(in.offset)) {
        throw std::invalid_argument(what + "non-finite scale or offset");
      }
      a->post[k] = in;
      a->post[k].texture = nullptr;
      clear[k] = clear[k] || in.scale != 1.0f || in.offset != 0.0f || in.srgb || in.nearest;
      a->width[k] = in.width;
      a->height[k] = in.height;
    } else if (!std::isfinite(in.alpha)) {
      throw std::invalid_argument(what + "non-finite alpha");
    }
    a->constant[k] = in.alpha;
    clear[k] = clear[k] || (in.texture == nullptr && in.alpha < 1.0f);
  }
  a->materials.assign(opacity.materials, opacity.materials + triangle_count);
  bool any = false;
  for (std::size_t j = 0; j < triangle_count; ++j) {
    const std::int32_t mat = a->materials[j];
    if (mat < -1 || mat >= static_cast<std::int32_t>(n)) {
      std::ostringstream s;
      s << "opacity materials[" << j << "] = " << mat << " outside [-1, " << n << ")";
      throw std::invalid_argument(s.str());
    }
    any = any || (mat >= 0 && clear[static_cast<std::size_t>(mat)]);
  }
  if (opacity.uvs != nullptr) {
    a->uvs.assign(opacity.uvs, opacity.uvs + 6 * triangle_count);
    for (float x : a->uvs) {
      if (!std::isfinite(x)) throw std::invalid_argument("opacity uvs: non-finite coordinate");
    }
  }
  return any ? std::move(a) : nullptr;
}
}  // namespace

RayTracer::RayTracer(PointsView vertices, const std::int32_t* triangles,
                     std::size_t triangle_count, const BakeShading& shading,
                     const Opacity& opacity, const std::vector<Prototype>& prototypes,
                     const std::vector<Instance>& instances, const RayTracerBuildOptions& build)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  StageTimer setup_timer("tracer: checks, copies");
  check_mesh(vertices, triangles, triangle_count, "");
  m.alpha = alpha_data(opacity, triangle_count);
  const PointsView vertex_normals = shading.vertex_normals;
  if (shading.polygons != nullptr && triangle_count > 0) {
    if (vertex_normals.size == 0) {
      throw std::invalid_argument("polygons need vertex_normals (they only group corners)");
    }
    m.polygons.assign(shading.polygons, shading.polygons + triangle_count);
  }
  if (vertex_normals.size != 0) {
    if (vertex_normals.size != vertices.size) {
      std::ostringstream s;
      s << "vertex_normals must have one row per vertex (" << vertices.size << "), got "
        << vertex_normals.size;
      throw std::invalid_argument(s.str());
    }
    check_points(vertex_normals, "vertex_normals");
    m.vertex_normals.resize(3 * vertex_normals.size);
    for (std::size_t i = 0; i < vertex_normals.size; ++i) {
      const Vec3 u = unit_or_zero(vertex_normals[i]);
      m.vertex_normals[3 * i] = u.x;
      m.vertex_normals[3 * i + 1] = u.y;
      m.vertex_normals[3 * i + 2] = u.z;
    }
  }
  if (shading.corner_normals != nullptr && triangle_count > 0) {
    if (vertex_normals.size == 0) {
      throw std::invalid_argument("corner_normals need vertex_normals (they shade bake points)");
    }
    const PointsView cn{shading.corner_normals, 3 * triangle_count};
    check_points(cn, "corner_normals");
    m.corner_normals.resize(9 * triangle_count);
    for (std::size_t i = 0; i < cn.size; ++i) {
      const Vec3 u = unit_or_zero(cn[i]);
      m.corner_normals[3 * i] = u.x;
      m.corner_normals[3 * i + 1] = u.y;
      m.corner_normals[3 * i + 2] = u.z;
    }
  }
  for (std::size_t k = 0; k < prototypes.size(); ++k) {
    const Prototype& p = prototypes[k];
    check_mesh(p.vertices, p.triangles, p.triangle_count,
               "prototype " + std::to_string(k) + ": ");
  }
  for (std::size_t k = 0; k < instances.size(); ++k) {
    const Instance& in = instances[k];
    std::ostringstream s;
    s << "instance " << k << ": ";
    if (in.prototype >= prototypes.size()) {
      s << "prototype " << in.prototype << " outside [0, " << prototypes.size() << ")";
      throw std::invalid_argument(s.str());
    }
    for (float x : in.matrix) {
      if (!std::isfinite(x)) throw std::invalid_argument(s.str() + "non-finite matrix entry");
    }
    const float* r = in.matrix + 12;  // the last row of an affine matrix: 0 0 0 1
    if (r[0] != 0.0f || r[1] != 0.0f || r[2] != 0.0f || r[3] != 1.0f) {
      throw std::invalid_argument(s.str() + "matrix is not affine (last row must be 0 0 0 1)");
    }
  }
  m.vertex_count = vertices.size;
  m.triangle_count = triangle_count;

  // Automatic origin offset: float precision of the intersection test, which scales with the
  // scene's extent and with its distance from the origin (a tree modelled 1 km away). Kept
  // small: it is also a bias, since occluders closer than it along the normal are skipped, and
  // a 200 m ground plane must not push a leaf's rays past its neighbour (1e-4·diag would be 3 cm).
  Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  float max_abs = 0;
  for (std::size_t i = 0; i < vertices.size; ++i) {
    const Vec3 p = vertices[i];
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], p[k]);
      hi[k] = std::max(hi[k], p[k]);
      max_abs = std::max(max_abs, std::fabs(p[k]));
    }
  }
  m.auto_offset = vertices.size ? 1e-5f * length(hi - lo) + 1e-6f * max_abs : 0.0f;
  m.precision = 1e-6f * max_abs;

  // 1. The device, with the error callback registered once so every call can be checked.
  m.device.reset(rtcNewDevice(nullptr));
  if (!m.device) {
    throw Error(std::string("Embree rtcNewDevice failed: ") +
                error_name(rtcGetDeviceError(nullptr)));
  }
  rtcSetDeviceErrorFunction(m.device.get(), record_error, m.errors.get());

  // 2. The scene: default flags (ROBUST costs a third of the speed, docs/DESIGN.md, 'Facts
  // measured in Blender'), except where vertex receivers start at Cycles' bake point: Cycles
  // builds ROBUST, whose hit test also counts a face through the ray's start (t = 0), and
  // without it a start lying in another face's plane would not see that face (a trunk's cap
  // in the ground: 0.44 against Cycles' 0.13, bench/cycles_contact.py).
  const bool robust = build.robust || !m.vertex_normals.empty();
  m.scene.reset(rtcNewScene(m.device.get()));
  m.check("rtcNewScene");
  rtcSetSceneFlags(m.scene.get(), robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(m.scene.get(),
                          build.high_quality ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
  m.check("scene setup");

  // 3. The triangles. An empty mesh makes an empty scene: every ray misses, AO = 1.
  m.vertices.resize(3 * vertices.size + 1, 0.0f);
  if (vertices.size) {
    std::copy(vertices.data, vertices.data + 3 * vertices.size, m.vertices.begin());
  }
  const bool culls =
      rtcGetDeviceProperty(m.device.get(), RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) != 0;
  if (triangle_count > 0) {
    two_sided_indices(triangles, triangle_count, culls, &m.indices);
    // The triangles using each vertex, in triangle order (where a vertex receiver starts).
    m.first_tri.assign(vertices.size + 1, 0);
    for (std::size_t i = 0; i < 3 * triangle_count; ++i) ++m.first_tri[m.indices[i] + 1];
    for (std::size_t v = 0; v < vertices.size; ++v) m.first_tri[v + 1] += m.first_tri[v];
    m.tris_of.resize(3 * triangle_count);
    std::vector<std::uint32_t> fill(m.first_tri.begin(), m.first_tri.end() - 1);
    for (std::size_t j = 0; j < triangle_count; ++j) {
      for (int k = 0; k < 3; ++k) {
        m.tris_of[fill[m.indices[3 * j + k]]++] = static_cast<std::uint32_t>(j);
      }
    }
    if (!m.vertex_normals.empty() && vertices.size > 0) {
      StageTimer corner_timer("tracer: corner tables");
      m.build_bake_corners(vertices.size);
    }
    // Both windings share primitive ids, so one filter on the original indices serves both
    // (the opacity's barycentrics swap on the second: AlphaData::flipped_geometry).
    if (m.alpha && culls) m.alpha->flipped_geometry = 1;
    for (int w = 0; w < (culls ? 2 : 1); ++w) {
      attach_triangles(m.device.get(), m.scene.get(), m.vertices.data(), vertices.size,
                       m.indices.data() + 3 * triangle_count * w, triangle_count,
                       skip_own_primitives);
    }
    m.check("geometry setup");
  }

  tbb::task_arena arena(max_threads());
  // 4a. Instanced meshes (Embree instances: RTC_GEOMETRY_TYPE_INSTANCE): one scene per
  // prototype, built once, placed by each instance's matrix. They only occlude: no receiver
  // lies on them, so they have no filter.
  for (const Prototype& p : prototypes) {
    auto pm = std::make_unique<Impl::Prototype>();
    pm->vertices.assign(3 * p.vertices.size + 1, 0.0f);
    if (p.vertices.size) std::copy(p.vertices.data, p.vertices.data + 3 * p.vertices.size,
                                   pm->vertices.begin());
    two_sided_indices(p.triangles, p.triangle_count, culls, &pm->indices);
    pm->scene.reset(rtcNewScene(m.device.get()));
    m.check("rtcNewScene (prototype)");
    rtcSetSceneFlags(pm->scene.get(), robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    rtcSetSceneBuildQuality(pm->scene.get(), build.high_quality ? RTC_BUILD_QUALITY_HIGH
                                                                : RTC_BUILD_QUALITY_MEDIUM);
    for (int w = 0; w < (culls && p.triangle_count ? 2 : 1) && p.triangle_count; ++w) {
      attach_triangles(m.device.get(), pm->scene.get(), pm->vertices.data(), p.vertices.size,
                       pm->indices.data() + 3 * p.triangle_count * w, p.triangle_count,
                       nullptr);
    }
    arena.execute([&] { rtcCommitScene(pm->scene.get()); });
    m.check("prototype setup");
    m.prototypes.push_back(std::move(pm));
  }
  for (const Instance& in : instances) {
    RTCGeometry geom = rtcNewGeometry(m.device.get(), RTC_GEOMETRY_TYPE_INSTANCE);
    m.check("rtcNewGeometry (instance)");
    rtcSetGeometryInstancedScene(geom, m.prototypes[in.prototype]->scene.get());
    rtcSetGeometryTransform(geom, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, in.matrix);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(m.scene.get(), geom);
    rtcReleaseGeometry(geom);
  }
  m.instance_count = instances.size();
  m.check("instance setup");

  // 4. The BVH build, on the caller's thread cap (Embree's TBB tasks join this arena).
  setup_timer.stop();
  StageTimer bvh_timer("tracer: BVH build");
  arena.execute([&] { rtcCommitScene(m.scene.get()); });
  m.check("rtcCommitScene");
}

RayTracer::~RayTracer() = default;
RayTracer::RayTracer(RayTracer&&) noexcept = default;
RayTracer& RayTracer::operator=(RayTracer&&) noexcept = default;

float RayTracer::auto_offset() const { return impl_->auto_offset; }
std::size_t RayTracer::vertex_count() const { return impl_->vertex_count; }
std::size_t RayTracer::triangle_count() const { return impl_->triangle_count; }
std::size_t RayTracer::instance_count() const { return impl_->instance_count; }
bool RayTracer::has_opacity() const { return impl_->alpha != nullptr; }
bool RayTracer::has_vertex_normals() const { return !impl_->vertex_normals.empty(); }

double RayTracer::corners_per_vertex() const {
  const Impl& m = *impl_;
  if (m.corner_first.empty()) return 1.0;
  std::uint64_t total = 0;
  for (std::size_t v = 0; v < m.vertex_count; ++v) total += m.corner_total(v);
  return static_cast<double>(total) / static_cast<double>(m.vertex_count);
}

namespace {
/// The rays one vertex with k corners casts at `samples` (RayTracer::ao's per-corner count).
std::int64_t vertex_ray_count(std::int64_t k, int samples, bool per_corner) {
  const std::int64_t wanted = per_corner && k > 1 ? samples * k : samples;
  return std::min<std::int64_t>(wanted, std::max<std::int64_t>(samples, kMaxRaysPerVertex));
}
}  // namespace

std::uint64_t RayTracer::vertex_rays(std::size_t first, std::size_t count, int samples) const {
  const Impl& m = *impl_;
  if (samples < 1) {
    throw std::invalid_argument("samples must be at least 1, got " + std::to_string(samples));
  }
  if (first > m.vertex_count || count > m.vertex_count - first) {
    std::ostringstream s;
    s << "vertices [" << first << ", " << first + count << ") are not in the tracer's "
      << m.vertex_count;
    throw std::invalid_argument(s.str());
  }
  if (m.corner_first.empty()) return static_cast<std::uint64_t>(count) * samples;
  std::uint64_t total = 0;
  for (std::size_t v = first; v < first + count; ++v) {
    total += static_cast<std::uint64_t>(vertex_ray_count(m.corner_total(v), samples, true));
  }
  return total;
}

std::vector<std::int32_t> RayTracer::vertex_corners(std::size_t first, std::size_t count) const {
  const Impl& m = *impl_;
  if (first > m.vertex_count || count > m.vertex_count - first) {
    std::ostringstream s;
    s << "vertices [" << first << ", " << first + count << ") are not in the tracer's "
      << m.vertex_count;
    throw std::invalid_argument(s.str());
  }
  std::vector<std::int32_t> out(count, 1);
  if (m.corner_first.empty()) return out;
  for (std::size_t i = 0; i < count; ++i) {
    out[i] = static_cast<std::int32_t>(vertex_ray_count(m.corner_total(first + i), 1, true));
  }
  return out;
}

// === Methods
void RayTracer::ao(PointsView points, PointsView normals, const RayTraceOptions& options,
                   float* out) const {
  ao(points, normals, OwnPrimitives{}, options, out);
}

void RayTracer::ao(PointsView points, PointsView normals, const OwnPrimitives& own,
                   const RayTraceOptions& options, float* out) const {
  ao(points, normals, own, options, out, nullptr);
}

void RayTracer::ao(PointsView points, PointsView normals, const OwnPrimitives& own,
                   const RayTraceOptions& options, float* out, float* bent) const {
  const Impl& m = *impl_;
  if (points.size != normals.size) {
    std::ostringstream s;
    s << "points and normals must have the same number of rows, got " << points.size << " and "
      << normals.size;
    throw std::invalid_argument(s.str());
  }
  if (options.samples < 1) {
    throw std::invalid_argument("samples must be at least 1, got " +
                                std::to_string(options.samples));
  }
  if (!(options.distance > 0)) {  // also rejects NaN
    throw std::invalid_argument("distance must be > 0 (inf = unlimited), got " +
                                std::to_string(options.distance));
  }
  if (std::isnan(options.offset) || std::isinf(options.offset)) {
    throw std::invalid_argument("offset must be finite (< 0 = automatic)");
  }
  if (options.point_group < 1) {
    throw std::invalid_argument("point_group must be at least 1, got " +
                                std::to_string(options.point_group));
  }
  for (std::size_t i = 0; options.point_samples && i < points.size; ++i) {
    if (options.point_samples[i] < 1) {
      std::ostringstream s;
      s << "point_samples[" << i << "] = " << options.point_samples[i] << ": each must be >= 1";
      throw std::invalid_argument(s.str());
    }
  }
  check_points(points, "points");
  check_points(normals, "normals");
  if (points.size > 0 && out == nullptr) throw std::invalid_argument("out is null");
  check_ids(own.vertex_ids, points.size, m.vertex_count, "vertex_ids", "vertex");
  check_ids(own.triangle_ids, points.size, m.triangle_count, "triangle_ids", "triangle");
  if ((own.vertex_ids || own.triangle_ids) && points.size > 0xffffffffu) {
    throw std::invalid_argument("too many points for 32-bit ray ids");
  }

  const std::size_t n = points.size;
  if (m.triangle_count == 0 && m.instance_count == 0) {
    std::fill(out, out + n, 1.0f);
    if (bent) finish_bent(normals, 0, n, nullptr, bent);  // nothing blocks: the normal
    return;
  }

  const int samples = options.samples;
  const std::size_t group = static_cast<std::size_t>(options.point_group);
  const bool automatic = options.offset < 0;
  const float offset = automatic ? m.auto_offset : options.offset;
  // Vertex receivers start at Cycles' bake point (raytrace.h, "Origins").
  const bool bake_point = automatic && (own.vertex_ids != nullptr || own.triangle_ids != nullptr) &&
                          !m.vertex_normals.empty();
  const float tfar = options.distance;  // +inf is fine for Embree
  const SampleSet set(samples);
  RTCScene scene = m.scene.get();
  const std::size_t grain =
      std::max<std::size_t>(1, kRaysPerBlock / static_cast<std::size_t>(samples));

  const bool profiling = stage_profiling();
  StageTimer wall_timer("rays: wall (all blocks)");
  parallel_for_blocks(n, grain, [&](std::size_t begin, std::size_t end) {
    // Profiling: this thread's CPU seconds in Embree's traversal (tracing), in the rest of the
    // loop (sampling: starts, directions, ray setup) and in the per-point division (reduction).
    const double block_start = profiling ? thread_cpu_seconds() : 0.0;
    double traversal = 0.0;
    // INV: rays[0..filled) belong to points owner[0..filled); hits are counted when flushed.
    alignas(64) RTCRay rays[kStream];
    std::uint32_t owner[kStream];
    std::vector<int> open(end - begin, 0), cast(end - begin, 1);
    std::vector<float> open_sum(bent ? 3 * (end - begin) : 0, 0.0f);  // Σ unblocked ω
    std::vector<float> xs(samples), ys(samples), zs(samples);
    // Per corner (RayTraceOptions::per_corner): k corners cast one set of k × samples rays; the
    // lattice of each size this block meets (other than `set`), built once per block.
    std::unordered_map<int, std::unique_ptr<SampleSet>> sets;
    std::size_t filled = 0;
    std::int32_t skip[kStream];  // bake-point mode: the triangle each batched ray skips
    std::vector<Corner> corners;
    TraceContext context;
    embree::init_context(&context.base);  // incoherent: AO rays go every way
    if (bake_point) {
      context.ray_skip = skip;
    } else {
      context.own_vertex = own.vertex_ids;
      context.own_triangle = own.triangle_ids;
    }
    context.indices = m.indices.data();
    context.alpha = m.alpha.get();

    auto flush = [&] {
      if (profiling) {
        const double t0 = thread_cpu_seconds();
        embree::occluded(scene, &context.base, rays, filled);
        traversal += thread_cpu_seconds() - t0;
      } else {
        embree::occluded(scene, &context.base, rays, filled);
      }
      for (std::size_t r = 0; r < filled; ++r) {
        // Embree sets tfar to -inf on an occluded ray.
        open[owner[r]] += rays[r].tfar >= 0.0f ? 1 : 0;
      }
      if (bent) accumulate_open(rays, owner, filled, open_sum.data());
      filled = 0;
    };

    for (std::size_t i = begin; i < end; ++i) {
      const Vec3 nn = unit_or_zero(normals[i]);
      if (!(length(nn) > 0.0f)) {  // zero normal: documented fallback, no hemisphere
        open[i - begin] = 1;
        continue;
      }
      Vec3 t, b;
      onb(nn, &t, &b);
      // The start (see raytrace.h, "Origins"): Cycles' bake point for a vertex when the tracer
      // has vertex normals, else on the receiver's own surface, else offset along the normal.
      const std::int32_t ov = own.vertex_ids ? own.vertex_ids[i] : -1;
      const std::int32_t ot = own.triangle_ids ? own.triangle_ids[i] : -1;
      corners.clear();
      if (bake_point && ov >= 0) {
        m.corners(static_cast<std::uint32_t>(ov), &corners);
      } else if (bake_point && ot >= 0) {
        Corner c;
        if (m.texel_corner(points[i], static_cast<std::uint32_t>(ot), nn, &c)) corners.push_back(c);
      }
      Vec3 o;
      std::int32_t own_skip = -1;
      if (automatic && ov >= 0 && !bake_point) {
        o = own_surface_origin(points[i], m.vertex_target(static_cast<std::uint32_t>(ov), nn),
                               m.precision);
      } else if (bake_point && ov >= 0) {
        // Used only when no triangle with area uses the vertex (a branch tip collapsed to a
        // point): a hair off it along its normal, Cycles' bake offset 1e-4 × max(1, |x|max),
        // since from the point itself every face meeting there blocks every ray at t = 0.
        o = points[i] + nn * Impl::bake_reach(points[i]);
      } else if (automatic && ot >= 0) {
        o = own_surface_origin(points[i], m.centroid(static_cast<std::uint32_t>(ot)),
                               m.precision);
        own_skip = ot;
      } else {
        o = points[i] + nn * offset;
        own_skip = ot;
      }
      const std::uint32_t local = static_cast<std::uint32_t>(i - begin);
      const std::size_t k = corners.size();
      // Per corner: k × samples, at most kMaxRaysPerVertex (or samples if more): a fan of
      // thousands of faces stays finite.
      const int samples_here = options.point_samples ? options.point_samples[i] : samples;
      const int rays_here = static_cast<int>(
          vertex_ray_count(static_cast<std::int64_t>(k), samples_here, options.per_corner));
      // A point of a group (RayTraceOptions::point_group; never a vertex) casts its share of
      // the group's set of max(count, g) directions: rays slot, slot + g, slot + 2g, ...
      const std::size_t g = ov < 0 ? group : 1;
      const std::size_t slot = i % g;
      const int set_rays = std::max(rays_here, static_cast<int>(g));
      const int own_rays = static_cast<int>((set_rays - slot + g - 1) / g);
      const SampleSet* here = &set;
      if (set_rays != samples && options.sampling == Sampling::kLattice) {
        std::unique_ptr<SampleSet>& built = sets[set_rays];
        if (!built) built = std::make_unique<SampleSet>(set_rays);
        here = built.get();
      }
      if (xs.size() < static_cast<std::size_t>(set_rays)) {
        xs.resize(set_rays);
        ys.resize(set_rays);
        zs.resize(set_rays);
      }
      cast[local] = own_rays;
      // Keyed by the vertex id where there is one: the same rays in any split into calls.
      const std::size_t key = ov >= 0 ? static_cast<std::size_t>(ov) : i / g;
      point_directions(options.sampling, *here, key, options.seed, set_rays, xs.data(),
                       ys.data(), zs.data());
      for (int s = 0; s < own_rays; ++s) {
        const std::size_t r = slot + g * static_cast<std::size_t>(s);
        const float x = xs[r], y = ys[r], z = zs[r];
        RTCRay& ray = rays[filled];
        Vec3 d, org = o;
        std::int32_t sk = own_skip;
        if (k) {  // Cycles' bake point: this ray's corner, and its terminator lift
          const Corner& c = corners[static_cast<std::size_t>(s) % k];
          if (c.open) {  // a NaN direction in Cycles: nothing stops it
            ++open[local];
            continue;
          }
          d = c.t * x + c.b * y + c.n * z;
          const float ngl = dot(c.ng, d), nl = z;
          const float amount =
              nl < kTerminatorCutoff
                  ? std::clamp(2.0f - (ngl + nl) / kTerminatorCutoff, 0.0f, 1.0f)
                  : std::clamp(1.0f - ngl / kTerminatorCutoff, 0.0f, 1.0f);
          org = c.start;
          sk = c.tri;
          if (amount > 0.0f) {
            org = c.start + c.lift * amount;
            if (!(ngl > 0.0f)) sk = -1;  // diving below its face: the face may stop it
          }
          // Cycles' integrate_surface_ray_offset: a ray that skips its own triangle but would
          // miss it by Cycles' own edge test (a start within rounding of an edge) leaves from
          // ray_offset instead, where no neighbouring face stops it at t = 0.
          if (sk >= 0 && !cycles_hits_self(org, d, c.V)) org = cycles_ray_offset(org, c.ng);
        } else {
          d = t * x + b * y + nn * z;
        }
        ray.dir_x = d.x;
        ray.dir_y = d.y;
        ray.dir_z = d.z;
        ray.org_x = org.x;
        ray.org_y = org.y;
        ray.org_z = org.z;
        ray.tnear = 0.0f;
        ray.time = 0.0f;
        ray.tfar = tfar;
        ray.mask = 0xffffffffu;
        // The filter's key: the receiver (its own primitives), or in bake-point mode the slot.
        ray.id = bake_point ? static_cast<unsigned>(filled) : static_cast<unsigned>(i);
        ray.flags = 0;
        skip[filled] = sk;
        owner[filled] = local;
        if (++filled == kStream) flush();
      }
      if (filled >= kMinStream) flush();
    }
    if (filled) flush();
    const double reduce_start = profiling ? thread_cpu_seconds() : 0.0;
    for (std::size_t i = begin; i < end; ++i) {
      out[i] = std::min(1.0f, static_cast<float>(open[i - begin]) /
                                  static_cast<float>(cast[i - begin]));
    }
    if (bent) finish_bent(normals, begin, end, open_sum.data(), bent);
    if (profiling) {
      const double block_end = thread_cpu_seconds();
      add_stage_seconds("rays: tracing (CPU)", traversal);
      add_stage_seconds("rays: sampling, starts (CPU)", reduce_start - block_start - traversal);
      add_stage_seconds("rays: reduction (CPU)", block_end - reduce_start);
    }
  });
  wall_timer.stop();
  m.check("rtcOccluded");
}

std::vector<float> RayTracer::ao(PointsView points, PointsView normals,
                                 const RayTraceOptions& options) const {
  std::vector<float> out(points.size);
  ao(points, normals, options, out.data());
  return out;
}

std::vector<float> RayTracer::ao_at_vertices(PointsView normals,
                                             const RayTraceOptions& options) const {
  if (normals.size != impl_->vertex_count) {
    std::ostringstream s;
    s << "normals must have one row per vertex (" << impl_->vertex_count << "), got "
      << normals.size;
    throw std::invalid_argument(s.str());
  }
  std::vector<std::int32_t> self(impl_->vertex_count);
  std::iota(self.begin(), self.end(), 0);
  OwnPrimitives own;
  own.vertex_ids = self.data();
  std::vector<float> out(impl_->vertex_count);
  ao(PointsView{impl_->vertices.data(), impl_->vertex_count}, normals, own, options, out.data());
  return out;
}

// === One-off
std::vector<float> ao_raytrace(PointsView vertices, const std::int32_t* triangles,
                               std::size_t triangle_count, PointsView points, PointsView normals,
                               const RayTraceOptions& options) {
  // Validate the cheap per-call settings before paying for a BVH build.
  if (options.samples < 1) {
    throw std::invalid_argument("samples must be at least 1, got " +
                                std::to_string(options.samples));
  }
  if (!(options.distance > 0)) {
    throw std::invalid_argument("distance must be > 0 (inf = unlimited), got " +
                                std::to_string(options.distance));
  }
  const RayTracer tracer(vertices, triangles, triangle_count);
  return tracer.ao(points, normals, options);
}

}  // namespace canopy_ao
