// Canopy AO — opaque convex patches as occluders (patches.h): core/walls.py's _form_factor,
// _clip and _lambert, step for step, one receiver at a time.
#include "canopy_ao/patches.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {

struct D3 {
  double x, y, z;
};
inline D3 operator-(D3 a, D3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline D3 operator+(D3 a, D3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline D3 operator*(double s, D3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline D3 cross(D3 a, D3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double norm(D3 a) { return std::sqrt(dot(a, a)); }

constexpr double kPi = 3.14159265358979323846;

/// A patch with what every receiver shares: its corners, normal and the in-plane axes u, v.
struct Prepared {
  std::vector<D3> corners;
  D3 m, u, v;
  D3 dirs[kPatchDiscSides];  // the disc polygon's sides' outward normals, in-plane
  double offset, eps;
};

Prepared prepare(const PatchPolygon& p) {
  Prepared q;
  for (std::size_t k = 0; k + 2 < p.corners.size(); k += 3)
    q.corners.push_back({p.corners[k], p.corners[k + 1], p.corners[k + 2]});
  q.m = {p.normal[0], p.normal[1], p.normal[2]};
  const D3 e = std::fabs(q.m.x) < 0.9 ? D3{1.0, 0.0, 0.0} : D3{0.0, 1.0, 0.0};
  q.u = cross(q.m, e);
  q.u = (1.0 / norm(q.u)) * q.u;
  q.v = cross(q.m, q.u);
  for (int k = 0; k < kPatchDiscSides; ++k) {
    const double ang = 2 * kPi * (k + 0.5) / kPatchDiscSides;
    q.dirs[k] = std::cos(ang) * q.u + std::sin(ang) * q.v;
  }
  q.offset = p.offset;
  q.eps = kPatchEps * p.diameter;
  return q;
}

/// poly (a convex polygon, in order) clipped to w · x >= c (Sutherland–Hodgman) into out;
/// false (out untouched) when every corner is inside: poly is its own clip.
bool clip(const std::vector<D3>& poly, D3 w, double c, std::vector<double>* side,
          std::vector<D3>* out) {
  const std::size_t k = poly.size();
  side->resize(k);
  bool all_in = true;
  for (std::size_t i = 0; i < k; ++i) {
    (*side)[i] = dot(poly[i], w) - c;
    all_in = all_in && (*side)[i] >= 0;
  }
  if (all_in) return false;
  out->clear();
  for (std::size_t i = 0; i < k; ++i) {
    const std::size_t j = i + 1 < k ? i + 1 : 0;
    const D3 a = poly[i], b = poly[j];
    const double sa = (*side)[i], sb = (*side)[j];
    const bool ina = sa >= 0, inb = sb >= 0;
    if (ina) out->push_back(a);
    if (ina != inb) out->push_back(a + (sa / (sa - sb)) * (b - a));
  }
  return true;
}

/// The form factor of a polygon (corners relative to the receiver): |Σ θ_i n · (a_i × a_i+1)
/// / |a_i × a_i+1|| / 2π over its edges, a_i the unit directions to its corners.
double lambert(const std::vector<D3>& poly, D3 n, std::vector<D3>* unit) {
  const std::size_t k = poly.size();
  if (k < 3) return 0.0;
  unit->resize(k);
  for (std::size_t i = 0; i < k; ++i)
    (*unit)[i] = (1.0 / std::max(norm(poly[i]), 1e-300)) * poly[i];
  double sum = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    const D3 a = (*unit)[i], b = (*unit)[i + 1 < k ? i + 1 : 0];
    const D3 c = cross(a, b);
    const double s = norm(c);
    if (s > 1e-12) sum += std::atan2(s, dot(a, b)) * dot(c, n) / s;
  }
  return std::min(std::fabs(sum) / (2 * kPi), 1.0);
}

/// Scratch polygons and per-corner values, one set per block of receivers.
struct Scratch {
  std::vector<D3> a, b, unit;
  std::vector<double> side;
};

/// The share of the receiver's (x, n) cosine-weighted hemisphere the patch covers within
/// `distance` of it (walls._form_factor).
double form_factor(const Prepared& q, D3 x, D3 n, double distance, Scratch* w) {
  std::vector<D3>* a = &w->a;
  std::vector<D3>* b = &w->b;
  double h = dot(x, q.m) - q.offset;
  if (!(std::fabs(h) < distance)) return 0.0;
  const double xn = dot(x, n);
  bool above = false;
  for (const D3& c : q.corners) above = above || (dot(c, n) - xn > q.eps);
  if (!above) return 0.0;
  if (std::fabs(h) < q.eps) {  // on the plane: a hair to its front
    x = x + (q.eps - h) * q.m;
    h = q.eps;
  }
  a->clear();
  for (const D3& c : q.corners) a->push_back(c - x);
  if (clip(*a, n, 0.0, &w->side, b)) std::swap(*a, *b);  // the receiver's hemisphere
  if (std::isfinite(distance)) {
    const double r2 = distance * distance - h * h;
    if (!(r2 > 0)) return 0.0;
    double far2 = 0.0;
    for (const D3& c : *a) far2 = std::max(far2, dot(c, c));
    if (far2 > distance * distance) {
      // the disc of radius sqrt(D² − h²) about the receiver's foot on the plane, as a
      // kPatchDiscSides-gon of its area: one half-space per side, dir its outward normal
      static const double area_scale =
          std::sqrt(2 * kPi / (kPatchDiscSides * std::sin(2 * kPi / kPatchDiscSides)));
      static const double inscribed = std::cos(kPi / kPatchDiscSides);
      const double r = std::sqrt(r2) * area_scale;
      const D3 foot = -h * q.m;
      for (const D3& dir : q.dirs) {
        const double lim = r * inscribed + dot(foot, dir);
        if (clip(*a, -1.0 * dir, -lim, &w->side, b)) std::swap(*a, *b);
      }
    }
  }
  return lambert(*a, n, &w->unit);
}

}  // namespace

void patch_visibility(const std::vector<PatchPolygon>& patches, const double* positions,
                      const double* normals, std::size_t n, double distance, double near,
                      float* out) {
  std::vector<Prepared> prepared;
  prepared.reserve(patches.size());
  for (const PatchPolygon& p : patches) prepared.push_back(prepare(p));
  parallel_for_blocks(n, 256, [&](std::size_t begin, std::size_t end) {
    Scratch scratch;
    for (std::size_t i = begin; i < end; ++i) {
      const D3 x{positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
      const D3 nn{normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]};
      double occ = 0.0;
      for (const Prepared& q : prepared) {
        occ += form_factor(q, x, nn, distance, &scratch);
        if (near > 0) occ -= form_factor(q, x, nn, near, &scratch);
      }
      const double v = 1.0 - occ;
      out[i] = static_cast<float>(v >= 0.0 ? std::min(v, 1.0) : 0.0);
    }
  });
}

}  // namespace canopy_ao
