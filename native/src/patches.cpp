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
  q.offset = p.offset;
  q.eps = kPatchEps * p.diameter;
  return q;
}

/// poly (a convex polygon, in order) clipped to w · x >= c (Sutherland–Hodgman) into out.
void clip(const std::vector<D3>& poly, D3 w, double c, std::vector<D3>* out) {
  out->clear();
  const std::size_t k = poly.size();
  for (std::size_t i = 0; i < k; ++i) {
    const D3 a = poly[i], b = poly[i + 1 < k ? i + 1 : 0];
    const double sa = dot(a, w) - c, sb = dot(b, w) - c;
    const bool ina = sa >= 0, inb = sb >= 0;
    if (ina) out->push_back(a);
    if (ina != inb) out->push_back(a + (sa / (sa - sb)) * (b - a));
  }
}

/// The form factor of a polygon (corners relative to the receiver): |Σ θ_i n · (a_i × a_i+1)
/// / |a_i × a_i+1|| / 2π over its edges, a_i the unit directions to its corners.
double lambert(const std::vector<D3>& poly, D3 n) {
  const std::size_t k = poly.size();
  if (k < 3) return 0.0;
  double sum = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    const D3 pa = poly[i], pb = poly[i + 1 < k ? i + 1 : 0];
    const D3 a = (1.0 / std::max(norm(pa), 1e-300)) * pa;
    const D3 b = (1.0 / std::max(norm(pb), 1e-300)) * pb;
    const D3 c = cross(a, b);
    const double s = norm(c);
    if (s > 1e-12) sum += std::atan2(s, dot(a, b)) * dot(c, n) / s;
  }
  return std::min(std::fabs(sum) / (2 * kPi), 1.0);
}

/// The share of the receiver's (x, n) cosine-weighted hemisphere the patch covers within
/// `distance` of it (walls._form_factor). a, b: scratch polygons.
double form_factor(const Prepared& q, D3 x, D3 n, double distance, std::vector<D3>* a,
                   std::vector<D3>* b) {
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
  clip(*a, n, 0.0, b);  // the receiver's hemisphere
  std::swap(*a, *b);
  if (std::isfinite(distance)) {
    const double r2 = distance * distance - h * h;
    if (!(r2 > 0)) return 0.0;
    double far = 0.0;
    for (const D3& c : *a) far = std::max(far, norm(c));
    if (far > distance) {
      // the disc of radius sqrt(D² − h²) about the receiver's foot on the plane, as a
      // kPatchDiscSides-gon of its area: one half-space per side, w its outward normal
      const double r = std::sqrt(r2) *
                       std::sqrt(2 * kPi / (kPatchDiscSides * std::sin(2 * kPi / kPatchDiscSides)));
      const D3 foot = -h * q.m;
      for (int k = 0; k < kPatchDiscSides; ++k) {
        const double ang = 2 * kPi * (k + 0.5) / kPatchDiscSides;
        const D3 w = std::cos(ang) * q.u + std::sin(ang) * q.v;
        const double lim = r * std::cos(kPi / kPatchDiscSides) + dot(foot, w);
        clip(*a, -1.0 * w, -lim, b);
        std::swap(*a, *b);
      }
    }
  }
  return lambert(*a, n);
}

}  // namespace

void patch_visibility(const std::vector<PatchPolygon>& patches, const double* positions,
                      const double* normals, std::size_t n, double distance, double near,
                      float* out) {
  std::vector<Prepared> prepared;
  prepared.reserve(patches.size());
  for (const PatchPolygon& p : patches) prepared.push_back(prepare(p));
  parallel_for_blocks(n, 256, [&](std::size_t begin, std::size_t end) {
    std::vector<D3> a, b;
    for (std::size_t i = begin; i < end; ++i) {
      const D3 x{positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
      const D3 nn{normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]};
      double occ = 0.0;
      for (const Prepared& q : prepared) {
        occ += form_factor(q, x, nn, distance, &a, &b);
        if (near > 0) occ -= form_factor(q, x, nn, near, &a, &b);
      }
      const double v = 1.0 - occ;
      out[i] = static_cast<float>(v >= 0.0 ? std::min(v, 1.0) : 0.0);
    }
  });
}

}  // namespace canopy_ao
