// Canopy AO — per-vertex occlusion features and their linear model (occlusion_features.h).
// No trapping math: the per-direction fast_exp loop must vectorise (fast_math.h's caveat).
#pragma GCC optimize("no-trapping-math")
#include "canopy_ao/occlusion_features.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

#include "canopy_ao/fast_math.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {

constexpr float kPi = 3.14159265358979f;
constexpr int kGridAO = 1;  // the feature the products pair with (grid AO at s = 1)
// The shape features (normal·up … distance from the mid-point) whose pairwise products join the
// expansion when the features are OcclusionFeatures' own (F = kCount).
constexpr int kShapeBegin = 6, kShapeEnd = 12;
constexpr int kShapePairs = (kShapeEnd - kShapeBegin) * (kShapeEnd - kShapeBegin - 1) / 2;

// Golden-angle spiral over the sphere: K nearly uniform directions, fixed (deterministic).
std::vector<Vec3> sphere_directions(int k) {
  std::vector<Vec3> d;
  const float golden = kPi * (3.0f - std::sqrt(5.0f));
  for (int i = 0; i < k; ++i) {
    const float z = 1.0f - (2.0f * i + 1.0f) / k;
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    d.push_back({r * std::cos(golden * i), r * std::sin(golden * i), z});
  }
  return d;
}

std::array<int, 3> level_dims(const DensityGrid& g, int level) {
  std::array<int, 3> d = {g.nx(), g.ny(), g.nz()};
  for (int l = 0; l < level; ++l) d = {(d[0] + 1) / 2, (d[1] + 1) / 2, (d[2] + 1) / 2};
  return d;
}

inline std::size_t vidx(const int* n, int i, int j, int k) {
  return (static_cast<std::size_t>(k) * n[1] + j) * n[0] + i;
}

// Lattice coordinates (voxel-centre units) of p.
inline Vec3 lattice(Vec3 origin, float h, Vec3 p) { return (p - origin) / h; }

inline bool inside_box(const int* n, Vec3 g) {
  return g.x >= -0.5f && g.y >= -0.5f && g.z >= -0.5f && g.x <= n[0] - 0.5f &&
         g.y <= n[1] - 0.5f && g.z <= n[2] - 0.5f;
}

}  // namespace

// --- Precomputation ----------------------------------------------------------------------------

OcclusionFeatures::Field OcclusionFeatures::sweep(const DensityGrid& g, int level,
                                                   const std::vector<Vec3>& dirs) {
  Field f;
  const std::array<int, 3> d = level_dims(g, level);
  // One empty voxel around the grid's box, which is tight on the geometry: σ and τ then fall
  // to 0 at the box's faces, so a receiver on the outermost leaf reads the same features just
  // inside the box as just outside it (features continuous in x: a scene and the same scaled
  // bake the same AO, whatever the resolution).
  f.n[0] = d[0] + 2, f.n[1] = d[1] + 2, f.n[2] = d[2] + 2;
  f.h = g.voxel_size() * static_cast<float>(1 << level);
  f.origin = g.origin() - Vec3{0.5f * f.h, 0.5f * f.h, 0.5f * f.h};
  {
    const std::vector<float>& inner = g.sigma_level(level);
    const int di[3] = {d[0], d[1], d[2]};
    f.sigma.assign(static_cast<std::size_t>(f.n[0]) * f.n[1] * f.n[2], 0.0f);
    for (int k = 0; k < d[2]; ++k)
      for (int j = 0; j < d[1]; ++j)
        for (int i = 0; i < d[0]; ++i)
          f.sigma[vidx(f.n, i + 1, j + 1, k + 1)] = inner[vidx(di, i, j, k)];
  }
  const std::size_t V = f.sigma.size(), K = dirs.size();
  const int* n = f.n;
  const std::size_t stride[3] = {1, static_cast<std::size_t>(n[0]),
                                 static_cast<std::size_t>(n[0]) * n[1]};
  // [direction][voxel]: each sweep writes its own direction's block, every voxel of it (no
  // zero fill). Lookups read the 8 corners of each direction's block (taus_at); with the
  // receivers in bucket order (coherent_order) those stay in cache, and no transpose to
  // [voxel][direction] (a pass over all K·V values, 40 % of the sweeps) is needed.
  f.tau.reset(new float[V * K]);
  parallel_for_blocks(K, 1, [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) {
      const Vec3 dk = dirs[k];
      int m = 0;
      for (int a = 1; a < 3; ++a)
        if (std::fabs(dk[a]) > std::fabs(dk[m])) m = a;
      // Lateral axes, the one with the smaller stride innermost (x whenever it is lateral).
      const int a1 = m == 0 ? 1 : 0, a2 = m == 2 ? 1 : 2;
      const int s = dk[m] > 0 ? 1 : -1;
      const float am = std::fabs(dk[m]);
      const float step = f.h / am;  // path length between slices
      // The upstream point sits one slice away, shifted laterally by a constant (da, db) voxels
      // (|da|, |db| <= 1): the same bilinear stencil for every voxel of the sweep.
      const float da = dk[a1] / am, db = dk[a2] / am;
      const int oa = static_cast<int>(std::floor(da)), ob = static_cast<int>(std::floor(db));
      const float fa = da - oa, fb = db - ob;
      const float wq[4] = {(1 - fa) * (1 - fb), fa * (1 - fb), (1 - fa) * fb, fa * fb};
      const std::size_t sa = stride[a1], sb = stride[a2];
      const float* sg = f.sigma.data();
      float* tp = f.tau.get() + k * V;
      // Columns ia whose four upstream corners all lie inside the slice: no bounds checks.
      const int ia_lo = std::max(0, -oa), ia_hi = std::min(n[a1] - 1, n[a1] - 2 - oa);
      // INV: every slice upstream of `im` (the side d_k points to) is final.
      for (int t = 0; t < n[m]; ++t) {
        const int im = s > 0 ? n[m] - 1 - t : t;
        const int up = im + s;
        const std::size_t base = im * stride[m];
        if (up < 0 || up >= n[m]) {  // the exit slice: half a step to the boundary
          for (int ib = 0; ib < n[a2]; ++ib)
            for (int ia = 0; ia < n[a1]; ++ia) {
              const std::size_t c = base + ia * sa + ib * sb;
              tp[c] = 0.5f * step * sg[c];
            }
          continue;
        }
        const std::size_t ubase = up * stride[m];
        for (int ib = 0; ib < n[a2]; ++ib) {
          auto checked = [&](int ia) {
            const std::size_t c = base + ia * sa + ib * sb;
            float tu = 0, su = 0;  // bilinear in the upstream slice, zero outside the grid
            for (int q = 0; q < 4; ++q) {
              const int ja = ia + oa + (q & 1), jb = ib + ob + (q >> 1);
              if (ja < 0 || jb < 0 || ja >= n[a1] || jb >= n[a2]) continue;
              const std::size_t u = ubase + ja * sa + jb * sb;
              tu += wq[q] * tp[u];
              su += wq[q] * sg[u];
            }
            tp[c] = tu + 0.5f * step * (sg[c] + su);
          };
          const bool row_inside = ib + ob >= 0 && ib + ob + 1 < n[a2];
          if (!row_inside || ia_lo > ia_hi) {
            for (int ia = 0; ia < n[a1]; ++ia) checked(ia);
            continue;
          }
          for (int ia = 0; ia < ia_lo; ++ia) checked(ia);
          const std::ptrdiff_t u0 = static_cast<std::ptrdiff_t>(ubase + (ib + ob) * sb) +
                                    static_cast<std::ptrdiff_t>(oa) * static_cast<std::ptrdiff_t>(sa);
          for (int ia = ia_lo; ia <= ia_hi; ++ia) {
            const std::size_t c = base + ia * sa + ib * sb;
            const std::size_t u = static_cast<std::size_t>(u0 + ia * static_cast<std::ptrdiff_t>(sa));
            const float tu = wq[0] * tp[u] + wq[1] * tp[u + sa] + wq[2] * tp[u + sb] +
                             wq[3] * tp[u + sa + sb];
            const float su = wq[0] * sg[u] + wq[1] * sg[u + sa] + wq[2] * sg[u + sb] +
                             wq[3] * sg[u + sa + sb];
            tp[c] = tu + 0.5f * step * (sg[c] + su);
          }
          for (int ia = ia_hi + 1; ia < n[a1]; ++ia) checked(ia);
        }
      }
    }
  });
  return f;
}

OcclusionFeatures::OcclusionFeatures(const DensityGrid& occluders,
                                     const OcclusionFeatureOptions& options) {
  if (options.directions < 6 || options.directions > 256) {
    throw std::invalid_argument("directions must be in [6, 256], got " +
                                std::to_string(options.directions));
  }
  dirs_ = sphere_directions(options.directions);
  fine_ = sweep(occluders, 0, dirs_);
}

// --- Lookups -----------------------------------------------------------------------------------

namespace {
// The trilinear stencil at lattice point g (clamped to the lattice): 8 voxel indices, weights.
void trilinear_stencil(const int* n, Vec3 g, std::size_t* idx, float* w) {
  int i0[3];
  float fr[3];
  for (int a = 0; a < 3; ++a) {
    const float x = std::clamp(g[a], 0.0f, static_cast<float>(n[a] - 1));
    i0[a] = std::min(static_cast<int>(x), std::max(n[a] - 2, 0));
    fr[a] = n[a] > 1 ? x - i0[a] : 0.0f;
  }
  for (int c = 0; c < 8; ++c) {
    int v[3];
    w[c] = 1;
    for (int a = 0; a < 3; ++a) {
      const int bit = (c >> a) & 1;
      v[a] = std::min(i0[a] + bit, n[a] - 1);
      w[c] *= bit ? fr[a] : 1 - fr[a];
    }
    idx[c] = vidx(n, v[0], v[1], v[2]);
  }
}
}  // namespace

float OcclusionFeatures::lerp3(const Field& f, const std::vector<float>& v, Vec3 g) {
  std::size_t idx[8];
  float w[8];
  trilinear_stencil(f.n, g, idx, w);
  float acc = 0;
  for (int c = 0; c < 8; ++c) acc += w[c] * v[idx[c]];
  return acc;
}

void OcclusionFeatures::taus_at(Vec3 p, float* tau) const {
  const Field& f = fine_;
  const int K = directions();
  const Vec3 g = lattice(f.origin, f.h, p);
  std::size_t idx[8];
  float w[8];
  if (inside_box(f.n, g)) {
    trilinear_stencil(f.n, g, idx, w);
    const std::size_t V = static_cast<std::size_t>(f.n[0]) * f.n[1] * f.n[2];
    for (int k = 0; k < K; ++k) {
      const float* src = f.tau.get() + k * V;
      float acc = 0;
      for (int c = 0; c < 8; ++c) acc += w[c] * src[idx[c]];
      tau[k] = acc;
    }
    return;
  }
  // Outside: the optical depth from where each direction enters the grid (slab test).
  for (int k = 0; k < K; ++k) {
    const Vec3 d = dirs_[k];
    float t0 = 0, t1 = std::numeric_limits<float>::infinity();
    bool miss = false;
    for (int a = 0; a < 3 && !miss; ++a) {
      const float lo = -0.5f, hi = f.n[a] - 0.5f;
      if (std::fabs(d[a]) < 1e-12f) {
        miss = g[a] < lo || g[a] > hi;
        continue;
      }
      float ta = (lo - g[a]) / d[a], tb = (hi - g[a]) / d[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    tau[k] = 0;
    if (miss || t0 > t1) continue;
    trilinear_stencil(f.n, g + d * t0, idx, w);
    const std::size_t V = static_cast<std::size_t>(f.n[0]) * f.n[1] * f.n[2];
    for (int c = 0; c < 8; ++c) tau[k] += w[c] * f.tau[k * V + idx[c]];
  }
}

void OcclusionFeatures::compute(PointsView positions, PointsView normals, const TreeFrame& frame,
                                float* out) const {
  if (positions.size != normals.size)
    throw std::invalid_argument("positions and normals must have the same number of rows");
  if (!(frame.radius > 0) || !std::isfinite(frame.radius) || !is_finite(frame.center) ||
      !std::isfinite(frame.z_min) || !std::isfinite(frame.z_max) || frame.z_max < frame.z_min)
    throw std::invalid_argument("frame needs a finite radius > 0 and z_min <= z_max");
  for (std::size_t i = 0; i < positions.size; ++i)
    if (!is_finite(positions[i]) || !is_finite(normals[i]))
      throw std::invalid_argument("positions and normals must be finite (row " +
                                  std::to_string(i) + ")");
  const int K = directions();
  const float height = std::max(frame.z_max - frame.z_min, 1e-12f);
  const Vec3 mid = {frame.center.x, frame.center.y, 0.5f * (frame.z_min + frame.z_max)};
  const float half_diag = std::max(0.5f * std::sqrt(4 * frame.radius * frame.radius +
                                                    height * height), 1e-12f);
  // The directions as columns, and the sky weights (d_k·z where upward), for the per-point loop.
  std::vector<float> dx(K), dy(K), dz(K), up(K);
  float w_sky = 0;
  for (int k = 0; k < K; ++k) {
    dx[k] = dirs_[k].x, dy[k] = dirs_[k].y, dz[k] = dirs_[k].z;
    up[k] = dirs_[k].z > 0 ? dirs_[k].z : 0.0f;
    w_sky += up[k];
  }
  const std::vector<std::uint32_t> order = coherent_order(positions);
  parallel_for_blocks(positions.size, 256, [&](std::size_t b, std::size_t e) {
    std::vector<float> taus(K), tr(K), sq(K);
    for (std::size_t j = b; j < e; ++j) {
      const std::size_t i = order[j];
      const Vec3 p = positions[i];
      const Vec3 nn = normalize(normals[i]);
      taus_at(p, taus.data());
      // exp(−τ) and its square root exp(−τ/2) for every direction: straight-line code that
      // GCC vectorises (libm's expf is a call it cannot).
      for (int k = 0; k < K; ++k) {
        tr[k] = fast_exp(-taus[k]);
        sq[k] = fast_exp(-0.5f * taus[k]);
      }
      // Branch-free sums (a direction adds 0 where its weight is not > 0) in kLanes partial
      // sums, direction k into lane k mod kLanes, added up in lane order at the end: a fixed
      // order (deterministic), and one GCC vectorises (a single running sum it may not
      // reorder).
      constexpr int kLanes = 8;
      float l_w[kLanes] = {}, l_s0[kLanes] = {}, l_s1[kLanes] = {}, l_s2[kLanes] = {},
            l_t[kLanes] = {}, l_ow[kLanes] = {}, l_o[kLanes] = {}, l_sky[kLanes] = {};
      auto add = [&](int l, int k) {
        const float w = nn.x * dx[k] + nn.y * dy[k] + nn.z * dz[k];
        const float wp = w > 0 ? w : 0.0f, wn = w < 0 ? -w : 0.0f;
        l_sky[l] += up[k] * tr[k];
        l_w[l] += wp;
        l_s0[l] += wp * sq[k];
        l_s1[l] += wp * tr[k];
        l_s2[l] += wp * tr[k] * tr[k];
        l_t[l] += wp * taus[k];
        l_ow[l] += wn;
        l_o[l] += wn * tr[k];
      };
      int k = 0;
      for (; k + kLanes <= K; k += kLanes)
        for (int l = 0; l < kLanes; ++l) add(l, k + l);
      for (int l = 0; k < K; ++k, ++l) add(l, k);
      float w_sum = 0, ao_s[3] = {0, 0, 0}, mean_tau = 0;
      float w_opp = 0, ao_opp = 0, sky = 0;
      for (int l = 0; l < kLanes; ++l) {
        w_sum += l_w[l];
        ao_s[0] += l_s0[l];
        ao_s[1] += l_s1[l];
        ao_s[2] += l_s2[l];
        mean_tau += l_t[l];
        w_opp += l_ow[l];
        ao_opp += l_o[l];
        sky += l_sky[l];
      }
      float* o = out + i * kCount;
      if (w_sum > 0) {
        for (int s = 0; s < 3; ++s) o[s] = ao_s[s] / w_sum;
        o[4] = std::log(1.0f + mean_tau / w_sum);  // logf: log1pf costs ~30 ns a call
      } else {  // zero normal: an open receiver
        o[0] = o[1] = o[2] = 1.0f;
        o[4] = 0.0f;
      }
      o[3] = w_sky > 0 ? sky / w_sky : 1.0f;
      const Vec3 gf = lattice(fine_.origin, fine_.h, p);
      const float sf = lerp3(fine_, fine_.sigma, gf) * fine_.h;
      o[5] = std::log(1.0f + (inside_box(fine_.n, gf) ? sf : 0.0f));
      const Vec3 r = {p.x - frame.center.x, p.y - frame.center.y, 0.0f};
      const float rl = length(r);
      o[6] = nn.z;
      o[7] = rl > 0 ? dot(nn, r) / rl : 0.0f;
      o[8] = std::clamp((p.z - frame.z_min) / height, -0.5f, 1.5f);
      o[9] = std::min(rl / frame.radius, 2.0f);
      const Vec3 q = p - mid;
      const float ql = length(q);
      o[10] = ql > 0 ? dot(nn, q) / ql : 0.0f;
      o[11] = std::min(ql / half_diag, 2.0f);
      o[12] = o[1] - (w_opp > 0 ? ao_opp / w_opp : 1.0f);
    }
  });
}

std::vector<std::uint32_t> OcclusionFeatures::coherent_order(PointsView positions) const {
  // Buckets of kBucket³ voxels (the lattice clamped, so points outside share the border's):
  // a counting sort by bucket, stable, so the order is deterministic. Points of a mesh come in
  // no spatial order (a crown's leaves anywhere), and each lookup reads 8 × K floats of a τ
  // field larger than the caches (24 MB for a 64³ grid); in bucket order consecutive points
  // read the same few voxels.
  constexpr int kBucket = 4;
  const Field& f = fine_;
  int nb[3];
  for (int a = 0; a < 3; ++a) nb[a] = (f.n[a] + kBucket - 1) / kBucket;
  const std::size_t N = positions.size, B = static_cast<std::size_t>(nb[0]) * nb[1] * nb[2];
  std::vector<std::uint32_t> key(N), count(B + 1, 0), order(N);
  for (std::size_t i = 0; i < N; ++i) {
    const Vec3 g = lattice(f.origin, f.h, positions[i]);
    int c[3];
    for (int a = 0; a < 3; ++a) {
      const float x = std::clamp(g[a], 0.0f, static_cast<float>(f.n[a] - 1));
      c[a] = std::min(static_cast<int>(x) / kBucket, nb[a] - 1);
    }
    key[i] = static_cast<std::uint32_t>(vidx(nb, c[0], c[1], c[2]));
    ++count[key[i] + 1];
  }
  for (std::size_t b = 0; b < B; ++b) count[b + 1] += count[b];
  for (std::size_t i = 0; i < N; ++i) order[count[key[i]]++] = static_cast<std::uint32_t>(i);
  return order;
}

const char* OcclusionFeatures::feature_name(int f) {
  static const char* names[kCount] = {
      "grid_ao_half", "grid_ao", "grid_ao_double", "sky_view", "log_depth", "density",
      "normal_up", "normal_radial", "height", "radial", "normal_out", "centre_distance",
      "open_side"};
  if (f < 0 || f >= kCount) throw std::invalid_argument("feature index out of range");
  return names[f];
}

// --- The linear model --------------------------------------------------------------------------

int expanded_size(int features) {
  return 3 * features + (features == OcclusionFeatures::kCount ? kShapePairs : 0);
}

namespace {
void check_model(int f, const float* scale) {
  if (f < 1) throw std::invalid_argument("at least one feature is needed");
  for (int j = 0; j < f; ++j)
    if (!(scale[j] > 0) || !std::isfinite(scale[j]))
      throw std::invalid_argument("scale must be finite and > 0 (feature " + std::to_string(j) +
                                  ")");
}

inline void expand_row(const float* x, int f, const float* mean, const float* scale, float* z,
                       float* phi) {
  for (int j = 0; j < f; ++j) z[j] = (x[j] - mean[j]) / scale[j];
  const int g = std::min(kGridAO, f - 1);
  int p = 0;
  phi[p++] = 1.0f;
  for (int j = 0; j < f; ++j) phi[p++] = z[j];
  for (int j = 0; j < f; ++j) phi[p++] = z[j] * z[j];
  for (int j = 0; j < f; ++j)
    if (j != g) phi[p++] = z[g] * z[j];
  if (f == OcclusionFeatures::kCount)
    for (int a = kShapeBegin; a < kShapeEnd; ++a)
      for (int b = a + 1; b < kShapeEnd; ++b) phi[p++] = z[a] * z[b];
}
}  // namespace

void expand_features(const float* features, std::size_t n, int f, const float* mean,
                     const float* scale, float* out) {
  check_model(f, scale);
  const int P = expanded_size(f);
  parallel_for_blocks(n, 1024, [&](std::size_t b, std::size_t e) {
    std::vector<float> z(f);
    for (std::size_t i = b; i < e; ++i)
      expand_row(features + i * f, f, mean, scale, z.data(), out + i * P);
  });
}

void predict_features(const float* features, std::size_t n, int f, const float* mean,
                      const float* scale, const float* weights, float* out) {
  predict_model(features, n, f, f, mean, scale, weights, nullptr, nullptr, out);
}

int model_size(int features, int native_features) {
  return expanded_size(native_features) + 3 * (features - native_features);
}

void predict_model(const float* features, std::size_t n, int f, int f_native, const float* mean,
                   const float* scale, const float* weights, const float* lo, const float* hi,
                   float* out) {
  if (f_native < 1 || f_native > f)
    throw std::invalid_argument("native_features must be in [1, features], got " +
                                std::to_string(f_native));
  check_model(f, scale);
  const int P = model_size(f, f_native);
  const int g = std::min(kGridAO, f_native - 1);
  parallel_for_blocks(n, 1024, [&](std::size_t b, std::size_t e) {
    std::vector<float> x(f), z(f), phi(P);
    for (std::size_t i = b; i < e; ++i) {
      const float* row = features + i * f;
      for (int j = 0; j < f; ++j)
        x[j] = lo != nullptr ? std::min(std::max(row[j], lo[j]), hi[j]) : row[j];
      expand_row(x.data(), f_native, mean, scale, z.data(), phi.data());
      // The extra columns: [z_e, z_e², z_grid·z_e], each group over the extra features.
      const int E = f - f_native, base = expanded_size(f_native);
      for (int j = 0; j < E; ++j) {
        const float ze = (x[f_native + j] - mean[f_native + j]) / scale[f_native + j];
        phi[base + j] = ze;
        phi[base + E + j] = ze * ze;
        phi[base + 2 * E + j] = ze * z[g];
      }
      double acc = 0;
      for (int p = 0; p < P; ++p) acc += static_cast<double>(weights[p]) * phi[p];
      out[i] = std::isfinite(acc) ? static_cast<float>(std::clamp(acc, 0.0, 1.0)) : 1.0f;
    }
  });
}

}  // namespace canopy_ao
