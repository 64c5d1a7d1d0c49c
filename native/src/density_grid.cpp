#include "canopy_ao/density_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"

namespace canopy_ao {
namespace {

constexpr float kTwoPi = 6.28318530717958647f;
constexpr float kMaxOpticalDepth = 20.0f;  // transmittance < 2e-9: stop marching
constexpr std::size_t kGrain = 256;

void require_finite_points(PointsView p, const char* name) {
  for (std::size_t i = 0; i < 3 * p.size; ++i) {
    if (!std::isfinite(p.data[i])) {
      std::ostringstream s;
      s << name << " has a non-finite value (NaN or inf) at row " << i / 3;
      throw std::invalid_argument(s.str());
    }
  }
}

// Area of triangle abc in double, the cross product's length scaled by its largest component:
// finite for any finite float vertices (float32 squares overflow from edges of ~1e10).
double triangle_area(Vec3 a, Vec3 b, Vec3 c) {
  double e1[3], e2[3];
  for (int k = 0; k < 3; ++k) e1[k] = double(b[k]) - a[k], e2[k] = double(c[k]) - a[k];
  const double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2],
               z = e1[0] * e2[1] - e1[1] * e2[0];
  return 0.5 * std::sqrt(x * x + y * y + z * z);
}

// splitmix64: a per-point random number from (index, seed), independent of threads.
inline std::uint64_t mix(std::uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Orthonormal basis around a unit normal (Duff et al. 2017, branchless, no singularity).
inline void basis(Vec3 n, Vec3* t1, Vec3* t2) {
  const float sign = std::copysign(1.0f, n.z);
  const float a = -1.0f / (sign + n.z);
  const float b = n.x * n.y * a;
  *t1 = {1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
  *t2 = {b, sign + n.y * n.y * a, -n.y};
}

// K cosine-weighted directions in the local frame (z = normal): a golden-angle spiral on the
// unit disc (equal areas), lifted to the hemisphere by Malley's method.
std::vector<Vec3> cosine_directions(int k) {
  std::vector<Vec3> d(k);
  const float golden = 2.39996322972865332f;
  for (int i = 0; i < k; ++i) {
    const float r2 = (i + 0.5f) / k;
    const float r = std::sqrt(r2);
    const float phi = golden * i;
    d[i] = {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0f, 1.0f - r2))};
  }
  return d;
}

}  // namespace

DensityGrid::DensityGrid(PointsView vertices, const std::int32_t* triangles,
                         std::size_t triangle_count, const DensityGridOptions& options) {
  const int res = options.resolution;
  if (res < 1 || res > 1024) {
    throw std::invalid_argument("resolution must be in [1, 1024], got " + std::to_string(res));
  }
  require_finite_points(vertices, "vertices");
  for (std::size_t i = 0; i < 3 * triangle_count; ++i) {
    if (triangles[i] < 0 || static_cast<std::size_t>(triangles[i]) >= vertices.size) {
      std::ostringstream s;
      s << "triangles row " << i / 3 << " has vertex index " << triangles[i] << ", outside [0, "
        << vertices.size << ")";
      throw std::invalid_argument(s.str());
    }
  }

  // Box of the triangles that have area (unreferenced or degenerate geometry adds nothing).
  Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  double area = 0;
  for (std::size_t t = 0; t < triangle_count; ++t) {
    const Vec3 a = vertices[triangles[3 * t]], b = vertices[triangles[3 * t + 1]],
               c = vertices[triangles[3 * t + 2]];
    const double at = triangle_area(a, b, c);
    if (!(at > 0)) continue;
    area += at;
    for (const Vec3& p : {a, b, c}) {
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
    }
  }
  if (!(area > 0)) {  // empty: one empty voxel, AO = 1 everywhere
    origin_ = {0, 0, 0};
    h_ = 1;
    dims_.push_back({1, 1, 1});
    sigma_.push_back({0.0f});
    return;
  }
  total_area_ = area;

  const Vec3 ext = hi - lo;
  h_ = std::max({ext.x, ext.y, ext.z}) / res;
  if (!(h_ >= kMinVoxel)) {  // 1/h and h³ would leave float's normal range
    std::ostringstream s;
    s << "the mesh's extent (" << h_ * res << ") is too small for a density grid at resolution "
      << res << " (voxel " << h_ << " < " << kMinVoxel << ")";
    throw std::invalid_argument(s.str());
  }
  std::array<int, 3> dims;
  for (int k = 0; k < 3; ++k) {
    dims[k] = std::clamp(static_cast<int>(std::ceil(ext[k] / h_ - 1e-4f)), 1, res);
    origin_[k] = lo[k] - 0.5f * (dims[k] * h_ - ext[k]);  // centre the box on the geometry
  }
  const std::size_t nvox = static_cast<std::size_t>(dims[0]) * dims[1] * dims[2];
  if (nvox > (std::size_t{1} << 26)) {  // 64M voxels: 256 MB of σ plus 512 MB while building
    throw std::invalid_argument("resolution " + std::to_string(res) + " gives " +
                                std::to_string(nvox) + " voxels (max 67108864): lower it");
  }
  dims_.push_back(dims);

  // Deposit area: m² equal sub-triangles per triangle (≥ 2 per voxel along its longest edge),
  // each at its centroid. Serial, so the sums do not depend on the thread count.
  std::vector<double> acc(nvox, 0.0);
  auto deposit = [&](Vec3 p, double a) {
    int idx[3];
    for (int k = 0; k < 3; ++k) {
      idx[k] = std::clamp(static_cast<int>(std::floor((p[k] - origin_[k]) / h_)), 0, dims[k] - 1);
    }
    acc[index(0, idx[0], idx[1], idx[2])] += a;
  };
  for (std::size_t t = 0; t < triangle_count; ++t) {
    const Vec3 a = vertices[triangles[3 * t]], b = vertices[triangles[3 * t + 1]],
               c = vertices[triangles[3 * t + 2]];
    const Vec3 e1 = b - a, e2 = c - a;
    const double at = triangle_area(a, b, c);
    if (!(at > 0)) continue;
    const float edge = std::max({length(e1), length(e2), length(c - b)});
    const int m = static_cast<int>(std::clamp(std::ceil(2.0f * edge / h_), 1.0f, 32.0f));
    const double sub = at / (static_cast<double>(m) * m);
    const float inv = 1.0f / m;
    for (int i = 0; i < m; ++i) {
      for (int j = 0; i + j < m; ++j) {
        deposit(a + e1 * ((i + 1.0f / 3) * inv) + e2 * ((j + 1.0f / 3) * inv), sub);
        if (i + j < m - 1) deposit(a + e1 * ((i + 2.0f / 3) * inv) + e2 * ((j + 2.0f / 3) * inv), sub);
      }
    }
  }
  // σ = leaf area density / 2 (random orientation: mean projected area = half the area).
  const double to_sigma = 1.0 / (2.0 * double(h_) * h_ * h_);
  std::vector<float> s0(nvox);
  for (std::size_t v = 0; v < nvox; ++v) s0[v] = static_cast<float>(acc[v] * to_sigma);
  sigma_.push_back(std::move(s0));

  // Mip pyramid: mean of the 2×2×2 children (missing children = empty), down to one voxel.
  while (std::max({dims_.back()[0], dims_.back()[1], dims_.back()[2]}) > 1) {
    const int l = static_cast<int>(dims_.size()) - 1;
    const std::array<int, 3> d = dims_.back();
    const std::array<int, 3> nd = {(d[0] + 1) / 2, (d[1] + 1) / 2, (d[2] + 1) / 2};
    dims_.push_back(nd);
    std::vector<float> s(static_cast<std::size_t>(nd[0]) * nd[1] * nd[2], 0.0f);
    for (int k = 0; k < nd[2]; ++k)
      for (int j = 0; j < nd[1]; ++j)
        for (int i = 0; i < nd[0]; ++i) {
          float sum = 0;
          for (int dk = 0; dk < 2; ++dk)
            for (int dj = 0; dj < 2; ++dj)
              for (int di = 0; di < 2; ++di) {
                const int ci = 2 * i + di, cj = 2 * j + dj, ck = 2 * k + dk;
                if (ci < d[0] && cj < d[1] && ck < d[2]) sum += sigma_[l][index(l, ci, cj, ck)];
              }
          s[index(l + 1, i, j, k)] = sum * 0.125f;
        }
    sigma_.push_back(std::move(s));
  }
}

bool DensityGrid::clip(Vec3 o, Vec3 d, float* t0, float* t1) const {
  const std::array<int, 3>& dims = dims_[0];
  for (int k = 0; k < 3; ++k) {
    const float lo = origin_[k], hi = origin_[k] + dims[k] * h_;
    if (std::abs(d[k]) < 1e-12f) {
      if (o[k] < lo || o[k] > hi) return false;
      continue;
    }
    const float inv = 1.0f / d[k];
    float ta = (lo - o[k]) * inv, tb = (hi - o[k]) * inv;
    if (ta > tb) std::swap(ta, tb);
    *t0 = std::max(*t0, ta);
    *t1 = std::min(*t1, tb);
  }
  return *t0 < *t1;
}

float DensityGrid::sample(int level, Vec3 p) const {
  const std::array<int, 3>& d = dims_[level];
  const float inv = 1.0f / (h_ * static_cast<float>(1 << level));
  int i0[3];
  float f[3];
  bool interior = true;
  for (int k = 0; k < 3; ++k) {
    const float q = (p[k] - origin_[k]) * inv - 0.5f;  // values sit at voxel centres
    const float fl = std::floor(q);
    i0[k] = static_cast<int>(fl);
    f[k] = q - fl;
    if (i0[k] < -1 || i0[k] >= d[k]) return 0.0f;  // wholly outside: empty
    interior = interior && i0[k] >= 0 && i0[k] + 1 < d[k];
  }
  const float* g = sigma_[level].data();
  if (interior) {  // all 8 corners inside: no per-corner checks
    const std::size_t sy = d[0], sz = static_cast<std::size_t>(d[0]) * d[1];
    const float* c = g + index(level, i0[0], i0[1], i0[2]);
    const float x00 = c[0] + (c[1] - c[0]) * f[0];
    const float x10 = c[sy] + (c[sy + 1] - c[sy]) * f[0];
    const float x01 = c[sz] + (c[sz + 1] - c[sz]) * f[0];
    const float x11 = c[sz + sy] + (c[sz + sy + 1] - c[sz + sy]) * f[0];
    const float y0 = x00 + (x10 - x00) * f[1], y1 = x01 + (x11 - x01) * f[1];
    return y0 + (y1 - y0) * f[2];
  }
  float v = 0;
  for (int c = 0; c < 8; ++c) {
    const int i = i0[0] + (c & 1), j = i0[1] + ((c >> 1) & 1), k = i0[2] + (c >> 2);
    if (i < 0 || j < 0 || k < 0 || i >= d[0] || j >= d[1] || k >= d[2]) continue;
    const float w = ((c & 1) ? f[0] : 1 - f[0]) * (((c >> 1) & 1) ? f[1] : 1 - f[1]) *
                    ((c >> 2) ? f[2] : 1 - f[2]);
    v += w * g[index(level, i, j, k)];
  }
  return v;
}

// Exact ∫ σ dt over [t0, t1] on the finest level: Amanatides–Woo 3D-DDA, each voxel's σ times
// the length of the ray inside it.
float DensityGrid::dda(Vec3 o, Vec3 d, float t0, float t1) const {
  if (!clip(o, d, &t0, &t1)) return 0.0f;
  const std::array<int, 3>& dims = dims_[0];
  int idx[3], step[3];
  float tmax[3], tdelta[3];
  for (int k = 0; k < 3; ++k) {
    const float g = (o[k] + d[k] * t0 - origin_[k]) / h_;
    idx[k] = std::clamp(static_cast<int>(std::floor(g)), 0, dims[k] - 1);
    // A component so small that h/d overflows never crosses a face: no steps along it (else
    // 0·inf = NaN below).
    const bool moves = d[k] != 0 && std::isfinite(h_ / d[k]);
    if (moves && d[k] > 0) {
      step[k] = 1;
      tdelta[k] = h_ / d[k];
      tmax[k] = t0 + (idx[k] + 1 - g) * tdelta[k];
    } else if (moves) {
      step[k] = -1;
      tdelta[k] = -h_ / d[k];
      tmax[k] = t0 + (g - idx[k]) * tdelta[k];
    } else {
      step[k] = 0;
      tdelta[k] = INFINITY;
      tmax[k] = INFINITY;
    }
  }
  const std::vector<float>& g = sigma_[0];
  float acc = 0, t = t0;
  // INV: the ray at t lies in voxel idx; tmax[k] is where it crosses the next k-face.
  while (t < t1) {
    const int a = (tmax[0] < tmax[1]) ? (tmax[0] < tmax[2] ? 0 : 2) : (tmax[1] < tmax[2] ? 1 : 2);
    const float te = std::min(tmax[a], t1);
    acc += g[index(0, idx[0], idx[1], idx[2])] * (te - t);
    t = te;
    idx[a] += step[a];
    if (idx[a] < 0 || idx[a] >= dims[a]) break;
    tmax[a] += tdelta[a];
  }
  return acc;
}

float DensityGrid::march(Vec3 o, Vec3 d, float t_min, float t_max, float skip_len,
                         float cone_tan, float limit) const {
  if (!(t_min < t_max)) return 0.0f;
  const int last = levels() - 1;
  float acc = 0;
  // 1. Own-leaf stretch on the diluted level, where the finest level has any density (so the
  //    coarse level's blur cannot reach a receiver just outside a dense block).
  float ts = std::min(skip_len, t_max);
  if (ts > t_min) {
    const Vec3 p = o + d * (0.5f * (t_min + ts));
    if (sample(0, p) > 0) acc += sample(std::min(2, last), p) * (ts - t_min);
  }
  ts = std::max(ts, t_min);
  // 2. Exact near field.
  const float te = std::min(std::max(kExactVoxels * h_, ts), t_max);
  if (te > ts) acc += dda(o, d, ts, te);
  // 3. Cone steps on coarser levels as the footprint grows.
  float t0 = te, t1 = t_max;
  if (!clip(o, d, &t0, &t1)) return acc;
  // March in u = t − t0, from the box entry: a receiver far outside the box (t0 ≫ h) would
  // otherwise stall once t + dt rounds to t. Every step but the last is ≥ h, so crossing the box
  // takes at most nx + ny + nz + 1 steps; the cap (twice that) only guards against round-off.
  const Vec3 entry = o + d * t0;
  const float span = t1 - t0;
  const int max_steps = 2 * (nx() + ny() + nz()) + 8;
  float u = 0;
  for (int step = 0; u < span && acc < limit && step < max_steps; ++step) {
    const float fp = 2.0f * cone_tan * (t0 + u) / h_;  // footprint in finest voxels
    const int l = fp >= 2.0f ? std::min(std::ilogb(fp), last) : 0;  // ⌊log2 fp⌋
    const float dt = std::min(h_ * static_cast<float>(1 << l), span - u);
    acc += sample(l, entry + d * (u + 0.5f * dt)) * dt;
    u += dt;
  }
  return acc;
}

float DensityGrid::optical_depth(Vec3 origin, Vec3 dir, float t_max, float self_skip,
                                 float cone_tan) const {
  return march(origin, normalize(dir), 0.0f, t_max, self_skip * h_, cone_tan, INFINITY);
}

void DensityGrid::ao(PointsView positions, PointsView normals, const DensityAOOptions& opt,
                     float* out) const {
  ao(positions, normals, opt, out, nullptr);
}

void DensityGrid::ao(PointsView positions, PointsView normals, const DensityAOOptions& opt,
                     float* out, float* bent) const {
  if (opt.directions < 1 || opt.directions > 4096) {
    throw std::invalid_argument("directions must be in [1, 4096], got " +
                                std::to_string(opt.directions));
  }
  if (std::isnan(opt.distance) || !(opt.distance > 0)) {
    throw std::invalid_argument("distance must be > 0 (inf = no cut-off)");
  }
  if (!std::isfinite(opt.sigma_scale) || opt.sigma_scale < 0) {
    throw std::invalid_argument("sigma_scale must be a finite number >= 0");
  }
  if (!std::isfinite(opt.start) || opt.start < 0) {
    throw std::invalid_argument("start must be a finite number >= 0");
  }
  if (!std::isfinite(opt.self_skip) || opt.self_skip < 0) {
    throw std::invalid_argument("self_skip must be a finite number >= 0");
  }
  if (positions.size != normals.size) {
    throw std::invalid_argument("positions and normals must have the same number of rows");
  }
  require_finite_points(positions, "positions");
  require_finite_points(normals, "normals");
  if (empty() || opt.sigma_scale == 0) {
    std::fill(out, out + positions.size, 1.0f);
    for (std::size_t i = 0; bent && i < positions.size; ++i) {  // nothing blocks: the normal
      const Vec3 n = normalize(normals[i]);
      bent[3 * i] = n.x;
      bent[3 * i + 1] = n.y;
      bent[3 * i + 2] = n.z;
    }
    return;
  }
  const int k = opt.directions;
  const std::vector<Vec3> dirs = cosine_directions(k);
  const float cone_tan = std::sqrt(2.0f / k);
  const float limit = kMaxOpticalDepth / opt.sigma_scale;
  const float skip_len = opt.self_skip * h_;
  const std::uint64_t seed = static_cast<std::uint64_t>(opt.seed) << 32;
  parallel_for_blocks(positions.size, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Vec3 x = positions[i];
      const Vec3 n = normalize(normals[i]);
      if (dot(n, n) == 0) {  // no hemisphere: open, like the ray-traced reference
        out[i] = 1.0f;
        if (bent) bent[3 * i] = bent[3 * i + 1] = bent[3 * i + 2] = 0.0f;
        continue;
      }
      Vec3 t1, t2;
      basis(n, &t1, &t2);
      const float psi = kTwoPi * static_cast<float>(mix(seed ^ i) >> 40) * (1.0f / (1 << 24));
      const float cs = std::cos(psi), sn = std::sin(psi);
      float sum = 0;
      Vec3 dir_sum{0.0f, 0.0f, 0.0f};  // Σ transmittance · ω (bent normal)
      for (const Vec3& l : dirs) {
        const float lx = cs * l.x - sn * l.y, ly = sn * l.x + cs * l.y;
        const Vec3 d = t1 * lx + t2 * ly + n * l.z;
        const float tr = std::exp(-opt.sigma_scale *
                                  march(x, d, opt.start, opt.distance, skip_len, cone_tan, limit));
        sum += tr;
        dir_sum = dir_sum + d * tr;
      }
      out[i] = std::clamp(sum / k, 0.0f, 1.0f);
      if (bent) {
        const float len = length(dir_sum);
        const Vec3 b = len > 0.0f ? dir_sum / len : n;
        bent[3 * i] = b.x;
        bent[3 * i + 1] = b.y;
        bent[3 * i + 2] = b.z;
      }
    }
  });
}

void ao_near_far(const RayTracer& tracer, const DensityGrid& grid, PointsView positions,
                 PointsView normals, float near, const RayTraceOptions& rt,
                 const DensityAOOptions& far, float* out) {
  ao_near_far(tracer, grid, positions, normals, near, OwnPrimitives{}, rt, far, out);
}

void ao_near_far(const RayTracer& tracer, const DensityGrid& grid, PointsView positions,
                 PointsView normals, float near, const OwnPrimitives& own,
                 const RayTraceOptions& rt, const DensityAOOptions& far, float* out) {
  if (!(near > 0) || std::isnan(near)) {
    throw std::invalid_argument("near must be > 0 (scene units)");
  }
  RayTraceOptions r = rt;
  r.distance = std::min(near, rt.distance);
  tracer.ao(positions, normals, own, r, out);
  DensityAOOptions f = far;
  f.distance = rt.distance;
  f.start = near;
  std::vector<float> tail(positions.size);
  grid.ao(positions, normals, f, tail.data());
  for (std::size_t i = 0; i < positions.size; ++i) out[i] *= tail[i];
}

}  // namespace canopy_ao
