// Canopy AO — per-vertex occlusion features and their linear model (occlusion_features.h).
// No trapping math: the per-direction fast_exp loop must vectorise (fast_math.h's caveat).
#pragma GCC optimize("no-trapping-math")
#include "canopy_ao/occlusion_features.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>

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
constexpr int kLanes = 8;    // partial sums of the per-direction loop (one AVX register)
constexpr int kBucket = 4;   // coherent_order's buckets: kBucket³ voxels
constexpr int kTileMin = 8;  // receivers of one bucket in a row that pay for its tile

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
          // Slices im and up never overlap: no dependence between iterations. Where the
          // lateral axis is x (stride 1, known at compile time) GCC vectorises the loop; the
          // arithmetic is the same element by element.
          auto interior = [&](auto sa_c) {
            const std::size_t sa1 = sa_c;
#pragma GCC ivdep
            for (int ia = ia_lo; ia <= ia_hi; ++ia) {
              const std::size_t c = base + ia * sa1 + ib * sb;
              const std::size_t u =
                  static_cast<std::size_t>(u0 + ia * static_cast<std::ptrdiff_t>(sa1));
              const float tu = wq[0] * tp[u] + wq[1] * tp[u + sa1] + wq[2] * tp[u + sb] +
                               wq[3] * tp[u + sa1 + sb];
              const float su = wq[0] * sg[u] + wq[1] * sg[u + sa1] + wq[2] * sg[u + sb] +
                               wq[3] * sg[u + sa1 + sb];
              tp[c] = tu + 0.5f * step * (sg[c] + su);
            }
          };
          if (sa == 1)
            interior(std::integral_constant<std::size_t, 1>{});
          else
            interior(sa);
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
// corner: null, or the lattice coordinates of corner 0 (corner q adds its bits, each clamped
// to the lattice's last layer).
inline void trilinear_stencil(const int* n, Vec3 g, std::size_t* idx, float* w,
                              int* corner = nullptr) {
  int i0[3];
  float fr[3];
  for (int a = 0; a < 3; ++a) {
    const float x = std::clamp(g[a], 0.0f, static_cast<float>(n[a] - 1));
    i0[a] = std::min(static_cast<int>(x), std::max(n[a] - 2, 0));
    fr[a] = n[a] > 1 ? x - i0[a] : 0.0f;
  }
  if (corner != nullptr)
    for (int a = 0; a < 3; ++a) corner[a] = i0[a];
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

// What one block of receivers reads (OcclusionFeatures::compute): the directions as columns
// padded with zeros to a multiple of kLanes (a padded direction adds +0 to every sum, which
// leaves it unchanged: the sums are ≥ 0), the frame's constants and the output.
struct OcclusionFeatures::FeatureContext {
  const OcclusionFeatures* self;
  PointsView positions, normals;
  const std::uint32_t* order;
  const std::uint32_t* bucket;  // bucket of order[j]
  int K, Kp;                    // directions, padded to a multiple of kLanes
  const float *dx, *dy, *dz, *up;
  float w_sky, height, half_diag;
  Vec3 mid;
  const TreeFrame* frame;
  float* out;
};

// One block of receivers (positions order[b..e)), the same arithmetic in the same order
// whichever instruction set compiles it: the AVX2 copy (namespace avx2) is built without FMA
// (no a·b+c contraction, which the x86-64-v2 baseline cannot do either), so both copies give the
// same bits (tests/cpp: OcclusionFeatures.*Kernels*).
//
// τ at a receiver inside the grid is the trilinear blend of its 8 lattice corners for every
// direction. The field is stored [direction][voxel] (the sweeps write it so), which costs 8 × K
// scattered reads per receiver; receivers come in bucket order (coherent_order), so a run of
// kTileMin or more in one bucket first copies the bucket's corner voxels (at most 5³) into a
// [voxel][direction] tile, and each then reads 8 rows of K contiguous values. Each τ_k sums
// its 8 corners in the same order either way.
__attribute__((always_inline)) inline void OcclusionFeatures::features_block(
    const FeatureContext& c, std::size_t b, std::size_t e, float* taus, float* tr, float* sq,
    float* tile) {
  const Field& f = c.self->fine_;
  const int K = c.K, Kp = c.Kp;
  const std::size_t V = static_cast<std::size_t>(f.n[0]) * f.n[1] * f.n[2];
  const std::size_t nb[3] = {static_cast<std::size_t>((f.n[0] + kBucket - 1) / kBucket),
                             static_cast<std::size_t>((f.n[1] + kBucket - 1) / kBucket), 0};
  std::uint32_t tile_bucket = UINT32_MAX;  // the bucket whose corners `tile` holds
  int lo[3] = {0, 0, 0}, ext[3] = {0, 0, 0};
  // The corners of bucket bk: lattice [lo, lo + ext) (a point's stencil in the bucket reads
  // corners from min(kBucket·b, n − 2) to min(kBucket·b + kBucket, n − 1) along each axis).
  auto corners_of = [&](std::uint32_t bk, int* l, int* x) {
    const std::size_t bc[3] = {bk % nb[0], (bk / nb[0]) % nb[1], bk / (nb[0] * nb[1])};
    for (int a = 0; a < 3; ++a) {
      l[a] = std::min(static_cast<int>(kBucket * bc[a]), std::max(f.n[a] - 2, 0));
      x[a] = std::min(static_cast<int>(kBucket * bc[a]) + kBucket, f.n[a] - 1) - l[a] + 1;
    }
  };
  // The next bucket's tile is fetched into the cache while this bucket's receivers are
  // computed (its rows spread over them), so copying it waits on no memory.
  int pf_lo[3] = {0, 0, 0}, pf_ext[3] = {0, 0, 0};
  std::size_t pf_row = 0, pf_rows = 0, pf_per = 0;
  for (std::size_t j = b; j < e; ++j) {
    const std::size_t i = c.order[j];
    // Receivers in bucket order lie anywhere in the arrays: fetch a later one's rows now.
    constexpr std::size_t kAhead = 8;
    if (j + kAhead < e) {
      const std::size_t ia = c.order[j + kAhead];
      __builtin_prefetch(c.positions.data + 3 * ia);
      __builtin_prefetch(c.normals.data + 3 * ia);
      __builtin_prefetch(c.out + ia * kCount, 1);
    }
    for (std::size_t r = 0; r < pf_per && pf_row < pf_rows; ++r, ++pf_row) {
      const std::size_t k = pf_row % K, yz = pf_row / K;
      const int y = static_cast<int>(yz % pf_ext[1]), z = static_cast<int>(yz / pf_ext[1]);
      const float* src = f.tau.get() + k * V + vidx(f.n, pf_lo[0], pf_lo[1] + y, pf_lo[2] + z);
      __builtin_prefetch(src);
      __builtin_prefetch(src + pf_ext[0] - 1);
    }
    const Vec3 p = c.positions[i];
    const Vec3 nn = normalize(c.normals[i]);
    const Vec3 g = lattice(f.origin, f.h, p);
    const std::uint32_t bk = c.bucket[j];
    bool tiled = false;
    if (inside_box(f.n, g)) {
      if (bk != tile_bucket) {
        std::size_t run = j + 1;
        while (run < e && c.bucket[run] == bk && run - j < kTileMin) ++run;
        if (run - j >= kTileMin) {  // copy the bucket's corners
          corners_of(bk, lo, ext);
          float* t = tile;
          for (int z = 0; z < ext[2]; ++z)
            for (int y = 0; y < ext[1]; ++y)
              for (int x = 0; x < ext[0]; ++x, t += Kp) {
                const float* src = f.tau.get() + vidx(f.n, lo[0] + x, lo[1] + y, lo[2] + z);
                for (int k = 0; k < K; ++k) t[k] = src[k * V];
                for (int k = K; k < Kp; ++k) t[k] = 0.0f;
              }
          tile_bucket = bk;
          while (run < e && c.bucket[run] == bk) ++run;
          if (run < e) {  // the next bucket's rows, a share at each receiver of this one
            corners_of(c.bucket[run], pf_lo, pf_ext);
            pf_row = 0;
            pf_rows = static_cast<std::size_t>(K) * pf_ext[1] * pf_ext[2];
            pf_per = (pf_rows + (run - j) - 1) / (run - j);
          }
        }
      }
      tiled = bk == tile_bucket;
    }
    float sigma_at = 0;  // σ at p (lerp3 of f.sigma), from the same stencil when tiled
    if (tiled) {
      std::size_t idx[8];
      float w[8];
      int corner[3];
      trilinear_stencil(f.n, g, idx, w, corner);
      for (int q = 0; q < 8; ++q) sigma_at += w[q] * f.sigma[idx[q]];
      for (int k = 0; k < Kp; ++k) taus[k] = 0.0f;
      for (int q = 0; q < 8; ++q) {
        // corner q of the stencil, clamped as trilinear_stencil clamps it, in the tile
        // INV: lo <= corner and corner + 1 <= lo + ext - 1 (clamped): the bucket's corners
        const int lx = std::min(corner[0] + (q & 1), f.n[0] - 1) - lo[0],
                  ly = std::min(corner[1] + ((q >> 1) & 1), f.n[1] - 1) - lo[1],
                  lz = std::min(corner[2] + (q >> 2), f.n[2] - 1) - lo[2];
        const float* row = tile + (static_cast<std::size_t>(lz * ext[1] + ly) * ext[0] + lx) * Kp;
        const float wq = w[q];
        for (int k = 0; k < Kp; ++k) taus[k] += wq * row[k];
      }
    } else {
      c.self->taus_at(p, taus);
      for (int k = K; k < Kp; ++k) taus[k] = 0.0f;
      sigma_at = lerp3(f, f.sigma, g);
    }
    // exp(−τ) and its square root exp(−τ/2) for every direction: straight-line code that
    // GCC vectorises (libm's expf is a call it cannot).
    for (int k = 0; k < Kp; ++k) {
      tr[k] = fast_exp(-taus[k]);
      sq[k] = fast_exp(-0.5f * taus[k]);
    }
    // Branch-free sums (a direction adds 0 where its weight is not > 0) in kLanes partial
    // sums, direction k into lane k mod kLanes, added up in lane order at the end: a fixed
    // order (deterministic), and one GCC vectorises (a single running sum it may not
    // reorder).
    float l_w[kLanes] = {}, l_s0[kLanes] = {}, l_s1[kLanes] = {}, l_s2[kLanes] = {},
          l_t[kLanes] = {}, l_ow[kLanes] = {}, l_o[kLanes] = {}, l_sky[kLanes] = {};
    for (int k0 = 0; k0 < Kp; k0 += kLanes)
      for (int l = 0; l < kLanes; ++l) {
        const int k = k0 + l;
        const float wd = nn.x * c.dx[k] + nn.y * c.dy[k] + nn.z * c.dz[k];
        const float wp = wd > 0 ? wd : 0.0f, wn = wd < 0 ? -wd : 0.0f;
        l_sky[l] += c.up[k] * tr[k];
        l_w[l] += wp;
        l_s0[l] += wp * sq[k];
        l_s1[l] += wp * tr[k];
        l_s2[l] += wp * tr[k] * tr[k];
        l_t[l] += wp * taus[k];
        l_ow[l] += wn;
        l_o[l] += wn * tr[k];
      }
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
    float* o = c.out + i * kCount;
    if (w_sum > 0) {
      for (int s = 0; s < 3; ++s) o[s] = ao_s[s] / w_sum;
      o[4] = std::log(1.0f + mean_tau / w_sum);  // logf: log1pf costs ~30 ns a call
    } else {  // zero normal: an open receiver
      o[0] = o[1] = o[2] = 1.0f;
      o[4] = 0.0f;
    }
    o[3] = c.w_sky > 0 ? sky / c.w_sky : 1.0f;
    const float sf = sigma_at * f.h;
    o[5] = std::log(1.0f + (inside_box(f.n, g) ? sf : 0.0f));
    const TreeFrame& frame = *c.frame;
    const Vec3 r = {p.x - frame.center.x, p.y - frame.center.y, 0.0f};
    const float rl = length(r);
    o[6] = nn.z;
    o[7] = rl > 0 ? dot(nn, r) / rl : 0.0f;
    o[8] = std::clamp((p.z - frame.z_min) / c.height, -0.5f, 1.5f);
    o[9] = std::min(rl / frame.radius, 2.0f);
    const Vec3 q = p - c.mid;
    const float ql = length(q);
    o[10] = ql > 0 ? dot(nn, q) / ql : 0.0f;
    o[11] = std::min(ql / c.half_diag, 2.0f);
    o[12] = o[1] - (w_opp > 0 ? ao_opp / w_opp : 1.0f);
  }
}

void OcclusionFeatures::features_portable(const FeatureContext& c, std::size_t b,
                                          std::size_t e, float* taus, float* tr, float* sq,
                                          float* tile) {
  features_block(c, b, e, taus, tr, sq, tile);
}

#ifdef CANOPY_AO_X86
// AVX2 without FMA: 8 directions a register, the same operations as the baseline's.
__attribute__((target("avx2"))) void OcclusionFeatures::avx2::features(
    const FeatureContext& c, std::size_t b, std::size_t e, float* taus, float* tr, float* sq,
    float* tile) {
  features_block(c, b, e, taus, tr, sq, tile);
}
#endif

namespace {
std::atomic<int> g_feature_kernel{-1};  // -1: pick on first use
}  // namespace

bool occlusion_features_kernel_avx2() {
  int k = g_feature_kernel.load(std::memory_order_relaxed);
  if (k < 0) {
#ifdef CANOPY_AO_X86
    k = __builtin_cpu_supports("avx2") ? 1 : 0;
#else
    k = 0;
#endif
    g_feature_kernel.store(k, std::memory_order_relaxed);
  }
  return k == 1;
}

void set_occlusion_features_kernel_avx2(bool on) {
#ifdef CANOPY_AO_X86
  if (on && !__builtin_cpu_supports("avx2"))
    throw std::invalid_argument("this CPU cannot run the AVX2 feature kernel");
#else
  if (on) throw std::invalid_argument("the AVX2 feature kernel needs an x86 CPU");
#endif
  g_feature_kernel.store(on ? 1 : 0, std::memory_order_relaxed);
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
  const int K = directions(), Kp = (K + kLanes - 1) / kLanes * kLanes;
  const float height = std::max(frame.z_max - frame.z_min, 1e-12f);
  const Vec3 mid = {frame.center.x, frame.center.y, 0.5f * (frame.z_min + frame.z_max)};
  const float half_diag = std::max(0.5f * std::sqrt(4 * frame.radius * frame.radius +
                                                    height * height), 1e-12f);
  // The directions as columns, and the sky weights (d_k·z where upward), for the per-point loop.
  std::vector<float> dx(Kp, 0.0f), dy(Kp, 0.0f), dz(Kp, 0.0f), up(Kp, 0.0f);
  float w_sky = 0;
  for (int k = 0; k < K; ++k) {
    dx[k] = dirs_[k].x, dy[k] = dirs_[k].y, dz[k] = dirs_[k].z;
    up[k] = dirs_[k].z > 0 ? dirs_[k].z : 0.0f;
    w_sky += up[k];
  }
  std::vector<std::uint32_t> bucket;
  const std::vector<std::uint32_t> order = coherent_order(positions, &bucket);
  const FeatureContext c{this, positions, normals, order.data(), bucket.data(), K, Kp,
                         dx.data(), dy.data(), dz.data(), up.data(), w_sky, height, half_diag,
                         mid, &frame, out};
  const bool avx2 = occlusion_features_kernel_avx2();
  parallel_for_blocks(positions.size, 256, [&](std::size_t b, std::size_t e) {
    std::vector<float> taus(Kp), tr(Kp), sq(Kp);
    std::vector<float> tile(static_cast<std::size_t>(kBucket + 1) * (kBucket + 1) *
                            (kBucket + 1) * Kp);
#ifdef CANOPY_AO_X86
    if (avx2) {
      avx2::features(c, b, e, taus.data(), tr.data(), sq.data(), tile.data());
      return;
    }
#endif
    (void)avx2;
    features_portable(c, b, e, taus.data(), tr.data(), sq.data(), tile.data());
  });
}

std::vector<std::uint32_t> OcclusionFeatures::coherent_order(
    PointsView positions, std::vector<std::uint32_t>* bucket) const {
  // Buckets of kBucket³ voxels (the lattice clamped, so points outside share the border's):
  // a counting sort by bucket, stable, so the order is deterministic. Points of a mesh come in
  // no spatial order (a crown's leaves anywhere), and each lookup reads 8 × K floats of a τ
  // field larger than the caches (24 MB for a 64³ grid); in bucket order consecutive points
  // read the same few voxels.
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
  if (bucket != nullptr) {
    bucket->resize(N);
    for (std::size_t j = 0; j < N; ++j) (*bucket)[j] = key[order[j]];
  }
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

namespace {
// predict_model's rows kRows at a time: the same terms in the same order as one row's
// expand_row and extra columns (each float product, then its double product with the weight,
// added to the row's double sum), laid out [term][row] so GCC vectorises across the rows.
constexpr int kRows = 8;
struct PredictArgs {
  const float* features;
  int f, f_native, g;
  const float *mean, *scale, *weights, *lo, *hi;
  float* out;
};

__attribute__((always_inline)) inline void predict_rows(const PredictArgs& a, std::size_t i0,
                                                         float* z) {
  const int f = a.f, fn = a.f_native, g = a.g;
  for (int j = 0; j < f; ++j)
    for (int r = 0; r < kRows; ++r) {
      const float v = a.features[(i0 + r) * f + j];
      const float x = a.lo != nullptr ? std::min(std::max(v, a.lo[j]), a.hi[j]) : v;
      z[j * kRows + r] = (x - a.mean[j]) / a.scale[j];
    }
  double acc[kRows];
  for (int r = 0; r < kRows; ++r) acc[r] = 0.0;
  int p = 0;
  auto term = [&](const float* zj) {  // φ_p = zj[r]
    const double w = a.weights[p++];
    for (int r = 0; r < kRows; ++r) acc[r] += w * static_cast<double>(zj[r]);
  };
  auto product = [&](const float* za, const float* zb) {  // φ_p = za[r]·zb[r]
    const double w = a.weights[p++];
    for (int r = 0; r < kRows; ++r) acc[r] += w * static_cast<double>(za[r] * zb[r]);
  };
  const float one[kRows] = {1, 1, 1, 1, 1, 1, 1, 1};
  term(one);
  for (int j = 0; j < fn; ++j) term(z + j * kRows);
  for (int j = 0; j < fn; ++j) product(z + j * kRows, z + j * kRows);
  for (int j = 0; j < fn; ++j)
    if (j != g) product(z + g * kRows, z + j * kRows);
  if (fn == OcclusionFeatures::kCount)
    for (int u = kShapeBegin; u < kShapeEnd; ++u)
      for (int v = u + 1; v < kShapeEnd; ++v) product(z + u * kRows, z + v * kRows);
  for (int j = fn; j < f; ++j) term(z + j * kRows);
  for (int j = fn; j < f; ++j) product(z + j * kRows, z + j * kRows);
  for (int j = fn; j < f; ++j) product(z + j * kRows, z + g * kRows);
  for (int r = 0; r < kRows; ++r)
    a.out[i0 + r] =
        std::isfinite(acc[r]) ? static_cast<float>(std::clamp(acc[r], 0.0, 1.0)) : 1.0f;
}

void predict_rows_portable(const PredictArgs& a, std::size_t i0, float* z) {
  predict_rows(a, i0, z);
}
}  // namespace

#ifdef CANOPY_AO_X86
namespace avx2 {
// AVX2 without FMA: the baseline's operations, four rows a register (the same bits).
__attribute__((target("avx2"))) void predict_rows(const PredictArgs& a, std::size_t i0,
                                                  float* z) {
  canopy_ao::predict_rows(a, i0, z);
}
}  // namespace avx2
#endif

void predict_model(const float* features, std::size_t n, int f, int f_native, const float* mean,
                   const float* scale, const float* weights, const float* lo, const float* hi,
                   float* out) {
  if (f_native < 1 || f_native > f)
    throw std::invalid_argument("native_features must be in [1, features], got " +
                                std::to_string(f_native));
  check_model(f, scale);
  const int P = model_size(f, f_native);
  const int g = std::min(kGridAO, f_native - 1);
  const PredictArgs args{features, f, f_native, g, mean, scale, weights, lo, hi, out};
  const bool avx2 = occlusion_features_kernel_avx2();
  parallel_for_blocks(n, 1024, [&](std::size_t b, std::size_t e) {
    std::vector<float> x(f), z(f), phi(P), zr(static_cast<std::size_t>(f) * kRows);
    std::size_t i = b;
    for (; i + kRows <= e; i += kRows) {  // blocks are multiples of kRows but the last
#ifdef CANOPY_AO_X86
      if (avx2) {
        avx2::predict_rows(args, i, zr.data());
        continue;
      }
#endif
      predict_rows_portable(args, i, zr.data());
    }
    (void)avx2;
    for (; i < e; ++i) {  // the last rows one by one: the same terms in the same order
      const float* row = features + i * f;
      for (int j = 0; j < f; ++j)
        x[j] = lo != nullptr ? std::min(std::max(row[j], lo[j]), hi[j]) : row[j];
      expand_row(x.data(), f_native, mean, scale, z.data(), phi.data());
      // The extra columns: [z_e, z_e², z_e·z_grid], each group over the extra features.
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
