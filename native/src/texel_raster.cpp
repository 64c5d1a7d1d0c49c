#include "canopy_ao/texel_raster.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

#include "canopy_ao/geometry.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {
namespace {

// Fixed point: UVs snapped to 1/256 texel. With |uv| ≤ 64 and W ≤ 16384, |coordinate| ≤ 2^28,
// so an edge function (difference of two products of 2^29-sized differences) fits in int64.
constexpr std::int64_t kSub = 256;
constexpr std::int64_t kHalf = kSub / 2;
constexpr float kMaxUv = 64.0f;
constexpr int kMaxResolution = 16384;

enum class TriStatus : std::uint8_t { Ok, Degenerate, InvalidUv, Outside };

// A triangle after setup: snapped, counter-clockwise, with its touched texel range.
struct Tri {
  std::int32_t x[3], y[3];   // texel-space coordinates × kSub
  std::int64_t area2 = 0;    // twice the signed area, > 0 once set up
  std::uint8_t corner[3];    // input corner (0..2) of each vertex (differs if mirrored)
  std::uint8_t bias[3];      // fill rule: edge k is inside on equality iff bias[k] == 0
  std::int32_t i0 = 0, i1 = -1, j0 = 0, j1 = -1;  // touched texels, clamped to the image
  TriStatus status = TriStatus::Outside;
};

std::int64_t floor_div(std::int64_t a, std::int64_t b) {
  const std::int64_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}
std::int64_t ceil_div(std::int64_t a, std::int64_t b) { return -floor_div(-a, b); }

// Edge k is opposite vertex k, from vertex k+1 to k+2. For a CCW triangle E_k > 0 inside and
// E_k(vertex k) = area2, so E_k / area2 is the barycentric weight of vertex k.
inline std::int64_t edge(const Tri& t, int k, std::int64_t px, std::int64_t py) {
  const int a = (k + 1) % 3, b = (k + 2) % 3;
  return static_cast<std::int64_t>(t.x[b] - t.x[a]) * (py - t.y[a]) -
         static_cast<std::int64_t>(t.y[b] - t.y[a]) * (px - t.x[a]);
}

inline bool centre_inside(const Tri& t, std::int64_t px, std::int64_t py) {
  for (int k = 0; k < 3; ++k) {
    if (edge(t, k, px, py) < t.bias[k]) return false;
  }
  return true;
}

Tri setup_triangle(const float* uv, int width, int height) {
  Tri t;
  for (int k = 0; k < 6; ++k) {
    if (!std::isfinite(uv[k]) || std::fabs(uv[k]) > kMaxUv) {
      t.status = TriStatus::InvalidUv;
      return t;
    }
  }
  std::int32_t x[3], y[3];
  for (int k = 0; k < 3; ++k) {
    // Exact in double (24-bit mantissa × 2^14 × 2^8), so shared corners snap identically.
    x[k] = static_cast<std::int32_t>(std::llround(double(uv[2 * k]) * width * kSub));
    y[k] = static_cast<std::int32_t>(std::llround(double(uv[2 * k + 1]) * height * kSub));
  }
  const std::int64_t area2 = std::int64_t(x[1] - x[0]) * (y[2] - y[0]) -
                             std::int64_t(y[1] - y[0]) * (x[2] - x[0]);
  if (area2 == 0) {
    t.status = TriStatus::Degenerate;
    return t;
  }
  // Mirrored UV islands are clockwise: swap two corners so every triangle is CCW.
  const std::uint8_t order[3] = {0, std::uint8_t(area2 > 0 ? 1 : 2), std::uint8_t(area2 > 0 ? 2 : 1)};
  for (int k = 0; k < 3; ++k) {
    t.x[k] = x[order[k]];
    t.y[k] = y[order[k]];
    t.corner[k] = order[k];
  }
  t.area2 = area2 > 0 ? area2 : -area2;
  for (int k = 0; k < 3; ++k) {
    const int a = (k + 1) % 3, b = (k + 2) % 3;
    const std::int64_t dx = t.x[b] - t.x[a], dy = t.y[b] - t.y[a];
    // Top-left rule: an edge owns the centres on it iff its direction lies in a fixed half-open
    // half-circle. The two triangles on a shared edge run it in opposite directions, so exactly
    // one of them owns it.
    const bool owns = dy < 0 || (dy == 0 && dx > 0);
    t.bias[k] = owns ? 0 : 1;
  }
  const std::int64_t minx = std::min({t.x[0], t.x[1], t.x[2]});
  const std::int64_t maxx = std::max({t.x[0], t.x[1], t.x[2]});
  const std::int64_t miny = std::min({t.y[0], t.y[1], t.y[2]});
  const std::int64_t maxy = std::max({t.y[0], t.y[1], t.y[2]});
  // Texels whose open square overlaps the bounding box (a superset of centre coverage).
  const std::int64_t i0 = std::max<std::int64_t>(0, floor_div(minx, kSub));
  const std::int64_t i1 = std::min<std::int64_t>(width - 1, ceil_div(maxx, kSub) - 1);
  const std::int64_t j0 = std::max<std::int64_t>(0, floor_div(miny, kSub));
  const std::int64_t j1 = std::min<std::int64_t>(height - 1, ceil_div(maxy, kSub) - 1);
  if (i0 > i1 || j0 > j1) {
    t.status = TriStatus::Outside;
    return t;
  }
  t.i0 = std::int32_t(i0);
  t.i1 = std::int32_t(i1);
  t.j0 = std::int32_t(j0);
  t.j1 = std::int32_t(j1);
  t.status = TriStatus::Ok;
  return t;
}

// x-extent of the triangle within the horizontal band y0 ≤ y ≤ y1: the band ∩ triangle is
// convex, its vertices are the triangle's vertices inside the band and the edges' crossings of
// the band's lines. Returns false if they do not meet.
bool band_extent(const Tri& t, double y0, double y1, double* xl, double* xr) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int k = 0; k < 3; ++k) {
    if (t.y[k] >= y0 && t.y[k] <= y1) {
      lo = std::min(lo, double(t.x[k]));
      hi = std::max(hi, double(t.x[k]));
    }
    const int a = k, b = (k + 1) % 3;
    const double ay = t.y[a], by = t.y[b];
    if (ay == by) continue;
    for (double yl : {y0, y1}) {
      if (yl >= std::min(ay, by) && yl <= std::max(ay, by)) {
        const double x = t.x[a] + (yl - ay) * double(t.x[b] - t.x[a]) / (by - ay);
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
    }
  }
  *xl = lo;
  *xr = hi;
  return lo <= hi;
}

// Barycentric weights of the point of triangle t closest to p (Ericson, Real-Time Collision
// Detection, §5.1.5 ClosestPtPointTriangle), in the snapped texel space.
void closest_barycentric(const Tri& t, double px, double py, double w[3]) {
  const double ax = t.x[0], ay = t.y[0], bx = t.x[1], by = t.y[1], cx = t.x[2], cy = t.y[2];
  const double abx = bx - ax, aby = by - ay, acx = cx - ax, acy = cy - ay;
  const double apx = px - ax, apy = py - ay;
  const double d1 = abx * apx + aby * apy, d2 = acx * apx + acy * apy;
  if (d1 <= 0 && d2 <= 0) {
    w[0] = 1, w[1] = 0, w[2] = 0;
    return;
  }
  const double bpx = px - bx, bpy = py - by;
  const double d3 = abx * bpx + aby * bpy, d4 = acx * bpx + acy * bpy;
  if (d3 >= 0 && d4 <= d3) {
    w[0] = 0, w[1] = 1, w[2] = 0;
    return;
  }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    w[0] = 1 - v, w[1] = v, w[2] = 0;
    return;
  }
  const double cpx = px - cx, cpy = py - cy;
  const double d5 = abx * cpx + aby * cpy, d6 = acx * cpx + acy * cpy;
  if (d6 >= 0 && d5 <= d6) {
    w[0] = 0, w[1] = 0, w[2] = 1;
    return;
  }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double s = d2 / (d2 - d6);
    w[0] = 1 - s, w[1] = 0, w[2] = s;
    return;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double s = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    w[0] = 0, w[1] = 1 - s, w[2] = s;
    return;
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, s = vc * denom;
  w[0] = 1 - v - s, w[1] = v, w[2] = s;
}

double distance2_to(const Tri& t, double px, double py) {
  double w[3];
  closest_barycentric(t, px, py, w);
  const double qx = w[0] * t.x[0] + w[1] * t.x[1] + w[2] * t.x[2];
  const double qy = w[0] * t.y[0] + w[1] * t.y[1] + w[2] * t.y[2];
  return (qx - px) * (qx - px) + (qy - py) * (qy - py);
}

// Covered texels of one strip of rows, in ascending pixel order.
struct StripTexels {
  std::vector<std::int32_t> pixels, triangles;
  std::vector<std::uint8_t> exact;
  std::size_t overlapping = 0;
};

void check_resolution(int width, int height) {
  if (width < 1 || width > kMaxResolution || height < 1 || height > kMaxResolution) {
    throw std::invalid_argument("resolution must be 1.." + std::to_string(kMaxResolution) +
                                " in each direction, got " + std::to_string(width) + " x " +
                                std::to_string(height));
  }
}

}  // namespace

TexelSet rasterize_uv(const CornerTriangles& in, const RasterOptions& options) {
  const int W = options.width, H = options.height;
  check_resolution(W, H);
  if (in.count > 0 && (in.uvs == nullptr || in.positions == nullptr)) {
    throw std::invalid_argument("rasterize_uv: uvs and positions are required");
  }
  if (in.count > std::size_t(std::numeric_limits<std::int32_t>::max())) {
    throw std::invalid_argument("rasterize_uv: more than 2^31 - 1 triangles");
  }
  TexelSet out;
  out.width = W;
  out.height = H;
  out.stats.triangles = in.count;
  const std::size_t M = in.count;

  // 1. Set up every triangle (parallel, independent).
  std::vector<Tri> tris(M);
  parallel_for_blocks(M, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) tris[t] = setup_triangle(in.uvs + 6 * t, W, H);
  });
  for (const Tri& t : tris) {
    out.stats.degenerate += t.status == TriStatus::Degenerate;
    out.stats.invalid_uv += t.status == TriStatus::InvalidUv;
  }

  // 2. Bin triangles into strips of rows: each strip is rasterised by one task with its own
  //    per-pixel buffers, so no two tasks touch the same pixel and the result is deterministic.
  //    Strips of ~64k pixels keep those buffers in cache.
  const int strip_rows = std::clamp(65536 / W, 1, 64);
  const std::size_t strips = (H + strip_rows - 1) / strip_rows;
  std::vector<std::size_t> bin_start(strips + 1, 0);
  for (const Tri& t : tris) {
    if (t.status != TriStatus::Ok) continue;
    for (int s = t.j0 / strip_rows; s <= t.j1 / strip_rows; ++s) ++bin_start[s + 1];
  }
  for (std::size_t s = 0; s < strips; ++s) bin_start[s + 1] += bin_start[s];
  std::vector<std::int32_t> bins(bin_start[strips]);
  {
    std::vector<std::size_t> fill(bin_start.begin(), bin_start.end() - 1);
    for (std::size_t i = 0; i < M; ++i) {
      const Tri& t = tris[i];
      if (t.status != TriStatus::Ok) continue;
      for (int s = t.j0 / strip_rows; s <= t.j1 / strip_rows; ++s) {
        bins[fill[s]++] = static_cast<std::int32_t>(i);  // ascending triangle id per strip
      }
    }
  }

  // 3. Rasterise the strips: exact centre coverage with the fill rule, then (conservative)
  //    the nearest touching triangle for texels no centre test claimed.
  std::vector<StripTexels> strip_out(strips);
  const bool conservative = options.conservative;
  parallel_for_blocks(strips, 1, [&](std::size_t sb, std::size_t se) {
    std::vector<std::int32_t> owner, near_tri;
    std::vector<std::uint8_t> multi;
    std::vector<double> near_d2;
    for (std::size_t s = sb; s < se; ++s) {
      const int r0 = int(s) * strip_rows, r1 = std::min(H, r0 + strip_rows);
      const std::size_t n = std::size_t(r1 - r0) * W;
      owner.assign(n, -1);
      multi.assign(n, 0);
      if (conservative) {
        near_tri.assign(n, -1);
        near_d2.assign(n, std::numeric_limits<double>::infinity());
      }
      for (std::size_t b = bin_start[s]; b < bin_start[s + 1]; ++b) {
        const std::int32_t id = bins[b];
        const Tri& t = tris[id];
        const int ja = std::max(r0, t.j0), jb = std::min(r1 - 1, t.j1);
        for (int j = ja; j <= jb; ++j) {
          double xl, xr;
          if (!band_extent(t, double(j) * kSub, double(j + 1) * kSub, &xl, &xr)) continue;
          // Touched texels: open square overlaps [xl, xr]. One more on each side for the exact
          // centre test, which is decided in integers, immune to the rounding of xl, xr.
          const int ta = int(std::floor(xl / kSub)), tb = int(std::ceil(xr / kSub)) - 1;
          const int ia = std::max(t.i0, ta - 1), ib = std::min(t.i1, tb + 1);
          const std::int64_t py = std::int64_t(j) * kSub + kHalf;
          std::size_t row = std::size_t(j - r0) * W;
          for (int i = ia; i <= ib; ++i) {
            const std::size_t p = row + i;
            const std::int64_t px = std::int64_t(i) * kSub + kHalf;
            if (centre_inside(t, px, py)) {
              if (owner[p] < 0) {
                owner[p] = id;
              } else {
                multi[p] = 1;
              }
            } else if (conservative && owner[p] < 0 && i >= ta && i <= tb) {
              const double d2 = distance2_to(t, double(px), double(py));
              if (d2 < near_d2[p]) {  // strict: ties keep the lower triangle id
                near_d2[p] = d2;
                near_tri[p] = id;
              }
            }
          }
        }
      }
      StripTexels& o = strip_out[s];
      std::size_t found = 0;  // reserve once: growing three vectors by doubling costs more
      for (std::size_t p = 0; p < n; ++p) found += owner[p] >= 0 || (conservative && near_tri[p] >= 0);
      o.pixels.reserve(found);
      o.triangles.reserve(found);
      o.exact.reserve(found);
      for (std::size_t p = 0; p < n; ++p) {
        const std::int32_t pixel = std::int32_t(std::size_t(r0) * W + p);
        if (owner[p] >= 0) {
          o.pixels.push_back(pixel);
          o.triangles.push_back(owner[p]);
          o.exact.push_back(1);
          o.overlapping += multi[p];
        } else if (conservative && near_tri[p] >= 0) {
          o.pixels.push_back(pixel);
          o.triangles.push_back(near_tri[p]);
          o.exact.push_back(0);
        }
      }
    }
  });

  // 4. Concatenate the strips in order.
  std::vector<std::size_t> offset(strips + 1, 0);
  for (std::size_t s = 0; s < strips; ++s) {
    offset[s + 1] = offset[s] + strip_out[s].pixels.size();
    out.stats.overlapping_texels += strip_out[s].overlapping;
  }
  const std::size_t T = offset[strips];
  out.pixels.resize(T);
  out.triangles.resize(T);
  out.exact.resize(T);
  parallel_for_blocks(strips, 16, [&](std::size_t sb, std::size_t se) {
    for (std::size_t s = sb; s < se; ++s) {
      StripTexels& o = strip_out[s];
      std::copy(o.pixels.begin(), o.pixels.end(), out.pixels.begin() + offset[s]);
      std::copy(o.triangles.begin(), o.triangles.end(), out.triangles.begin() + offset[s]);
      std::copy(o.exact.begin(), o.exact.end(), out.exact.begin() + offset[s]);
      o = StripTexels();
    }
  });
  for (std::uint8_t e : out.exact) out.stats.exact_texels += e;
  out.stats.conservative_texels = T - out.stats.exact_texels;

  // 5. Interpolate position and normal at every texel (parallel, each texel on its own).
  out.barycentrics.resize(3 * T);
  out.positions.resize(3 * T);
  out.normals.resize(3 * T);
  parallel_for_blocks(T, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t n = b; n < e; ++n) {
      const std::int32_t id = out.triangles[n];
      const Tri& t = tris[id];
      const std::int32_t pixel = out.pixels[n];  // 32-bit division: pixel < 2^28
      const std::int64_t px = std::int64_t(pixel % W) * kSub + kHalf;
      const std::int64_t py = std::int64_t(pixel / W) * kSub + kHalf;
      double w[3];
      if (out.exact[n]) {
        const double inv_area2 = 1.0 / double(t.area2);
        for (int k = 0; k < 3; ++k) w[k] = double(edge(t, k, px, py)) * inv_area2;
      } else {
        closest_barycentric(t, double(px), double(py), w);
      }
      float bc[3];  // by input corner
      for (int k = 0; k < 3; ++k) bc[t.corner[k]] = float(w[k]);
      const std::size_t c0 = 3 * std::size_t(id);
      const PointsView P{in.positions + 3 * c0, 3};
      Vec3 pos = P[0] * bc[0] + P[1] * bc[1] + P[2] * bc[2];
      Vec3 nrm{0, 0, 0};
      if (in.normals != nullptr) {
        const PointsView N{in.normals + 3 * c0, 3};
        nrm = N[0] * bc[0] + N[1] * bc[1] + N[2] * bc[2];
      }
      // Interpolated corner normal, else the face normal, else +z: always unit length (a
      // triangle with no area in 3D and vanishing normals has no direction of its own).
      nrm = normalize(nrm);
      if (dot(nrm, nrm) == 0) nrm = normalize(cross(P[1] - P[0], P[2] - P[0]));
      if (dot(nrm, nrm) == 0) nrm = Vec3{0, 0, 1};
      for (int k = 0; k < 3; ++k) {
        out.barycentrics[3 * n + k] = bc[k];
        out.positions[3 * n + k] = pos[k];
        out.normals[3 * n + k] = nrm[k];
      }
    }
  });
  return out;
}

// === Splat and margin

TexelImage splat_texels(const std::int32_t* pixels, const float* values, std::size_t count,
                        int channels, int width, int height, int margin, float background) {
  check_resolution(width, height);
  if (channels < 1 || channels > 4) {
    throw std::invalid_argument("channels must be 1..4, got " + std::to_string(channels));
  }
  if (margin < 0) throw std::invalid_argument("margin must be >= 0, got " + std::to_string(margin));
  if (!std::isfinite(background)) throw std::invalid_argument("background must be finite");
  if (count > 0 && (pixels == nullptr || values == nullptr)) {
    throw std::invalid_argument("splat_texels: pixels and values are required");
  }
  const std::size_t npix = std::size_t(width) * height;
  for (std::size_t n = 0; n < count; ++n) {
    if (pixels[n] < 0 || std::size_t(pixels[n]) >= npix) {
      throw std::invalid_argument("pixel index " + std::to_string(pixels[n]) + " at texel " +
                                  std::to_string(n) + " is outside the " +
                                  std::to_string(width) + " x " + std::to_string(height) +
                                  " image");
    }
  }
  for (std::size_t k = 0; k < count * channels; ++k) {
    if (!std::isfinite(values[k])) {
      throw std::invalid_argument("values has a non-finite value (NaN or inf) at texel " +
                                  std::to_string(k / channels));
    }
  }
  TexelImage r;
  r.image.width = width;
  r.image.height = height;
  r.image.channels = channels;
  r.image.pixels.assign(npix * channels, background);
  r.mask.assign(npix, kTexelEmpty);
  // Serial: a pixel given twice must deterministically keep the later value.
  for (std::size_t n = 0; n < count; ++n) {
    const std::size_t p = std::size_t(pixels[n]);
    std::memcpy(&r.image.pixels[p * channels], values + n * channels, sizeof(float) * channels);
    r.mask[p] = kTexelCovered;
  }
  dilate_margin(r.image, r.mask, margin);
  return r;
}

void dilate_margin(Image& image, std::vector<std::uint8_t>& mask, int margin) {
  if (mask.size() != std::size_t(image.width) * image.height ||
      image.pixels.size() != mask.size() * image.channels) {
    throw std::invalid_argument("dilate_margin: image and mask sizes differ");
  }
  dilate_margin(image.pixels.data(), mask.data(), image.width, image.height, image.channels,
                margin);
}

void dilate_margin(float* pixels, std::uint8_t* mask, int W, int H, int C, int margin) {
  check_resolution(W, H);
  if (C < 1 || C > 4) throw std::invalid_argument("channels must be 1..4");
  if (margin < 0) throw std::invalid_argument("margin must be >= 0, got " + std::to_string(margin));
  if (margin == 0) return;
  // Frontier: empty pixels with a filled 8-neighbour. Only it is visited each ring, so the cost
  // grows with the islands' perimeter, not the image area. A queued pixel is marked kQueued so
  // it enters the next frontier once; it still counts as empty for averaging.
  constexpr std::uint8_t kQueued = 0xFF;
  auto filled = [&](std::size_t q) { return mask[q] != kTexelEmpty && mask[q] != kQueued; };
  auto for_neighbours = [&](std::size_t p, auto&& f) {
    const int x = int(p % W), y = int(p / W);
    for (int dy = -1; dy <= 1; ++dy) {
      const int yy = y + dy;
      if (yy < 0 || yy >= H) continue;
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = x + dx;
        if ((dx == 0 && dy == 0) || xx < 0 || xx >= W) continue;
        f(std::size_t(yy) * W + xx);
      }
    }
  };

  // Initial frontier, rows in parallel, concatenated in row order.
  const std::size_t rows_per_block = 16;
  const std::size_t blocks = (H + rows_per_block - 1) / rows_per_block;
  std::vector<std::vector<std::size_t>> found(blocks);
  parallel_for_blocks(blocks, 1, [&](std::size_t bb, std::size_t be) {
    for (std::size_t b = bb; b < be; ++b) {
      const std::size_t y0 = b * rows_per_block, y1 = std::min<std::size_t>(H, y0 + rows_per_block);
      for (std::size_t p = y0 * W; p < y1 * W; ++p) {
        if (mask[p] != kTexelEmpty) continue;
        bool near = false;
        for_neighbours(p, [&](std::size_t q) { near = near || filled(q); });
        if (near) found[b].push_back(p);
      }
    }
  });
  std::vector<std::size_t> frontier;
  for (auto& f : found) frontier.insert(frontier.end(), f.begin(), f.end());
  found.clear();
  for (std::size_t p : frontier) mask[p] = kQueued;

  std::vector<float> values;
  for (int ring = 0; ring < margin && !frontier.empty(); ++ring) {
    // INV: every frontier pixel is kQueued and has a filled neighbour; filled pixels are not
    // modified until all frontier values are computed (Jacobi step: order-independent).
    values.assign(frontier.size() * C, 0.0f);
    parallel_for_blocks(frontier.size(), 1024, [&](std::size_t b, std::size_t e) {
      for (std::size_t n = b; n < e; ++n) {
        double sum[4] = {0, 0, 0, 0};  // double: 8 values near float's max cannot overflow
        int k = 0;
        for_neighbours(frontier[n], [&](std::size_t q) {
          if (!filled(q)) return;
          for (int c = 0; c < C; ++c) sum[c] += pixels[q * C + c];
          ++k;
        });
        for (int c = 0; c < C; ++c) values[n * C + c] = static_cast<float>(sum[c] / k);
      }
    });
    for (std::size_t n = 0; n < frontier.size(); ++n) {
      std::memcpy(pixels + frontier[n] * C, &values[n * C], sizeof(float) * C);
      mask[frontier[n]] = kTexelMargin;
    }
    if (ring + 1 == margin) break;
    std::vector<std::size_t> next;
    for (std::size_t p : frontier) {
      for_neighbours(p, [&](std::size_t q) {
        if (mask[q] == kTexelEmpty) {
          mask[q] = kQueued;
          next.push_back(q);
        }
      });
    }
    frontier.swap(next);
  }
  // Pixels queued for a ring that never came stay background.
  for (std::size_t p : frontier) {
    if (mask[p] == kQueued) mask[p] = kTexelEmpty;
  }
}

}  // namespace canopy_ao
