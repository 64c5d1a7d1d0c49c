// Canopy AO — small geometry types shared by every part of the core.
//
// Conventions used across the library:
//  - points and normals are float32, packed xyz (an N×3 row-major array), world space;
//  - AO / visibility values are in [0, 1]: 1 = fully open sky, 0 = fully blocked;
//  - bad input throws std::invalid_argument (Python: ValueError); library failures throw
//    canopy_ao::Error (Python: canopy_ao.CanopyAOError, a RuntimeError);
//  - accepted range (checked at the Python boundary, native/python/arrays.h): coordinates
//    within ±1e9, lengths in [1e-9, 1e10], τ in [0, 1e4], normals of any finite length. Within
//    it every function returns finite values; C++ callers outside it get no such promise.
#pragma once

#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>

namespace canopy_ao {

// === Errors
/// A failure inside the library (Embree, OpenImageIO, ...), as opposed to bad input.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// === Vectors
struct Vec3 {
  float x = 0, y = 0, z = 0;
  Vec3() = default;
  constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
  float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};
inline Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
inline Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
inline Vec3 operator*(float s, Vec3 a) { return a * s; }
inline Vec3 operator/(Vec3 a, float s) { return a * (1.0f / s); }
inline float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(Vec3 a) { return std::sqrt(dot(a, a)); }
/// Unit vector along a, or 0 for a zero (or non-finite) vector. Scaled by the largest
/// component before squaring, so lengths from the smallest denormal to float's max normalise
/// exactly (squaring first overflows above ~1.8e19 and vanishes below ~1e-19).
inline Vec3 normalize(Vec3 a) {
  const float m = std::fmax(std::fabs(a.x), std::fmax(std::fabs(a.y), std::fabs(a.z)));
  if (!(m > 0) || !std::isfinite(m)) return Vec3{0, 0, 0};
  const Vec3 b{a.x / m, a.y / m, a.z / m};
  return b / length(b);
}
inline bool is_finite(Vec3 a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

/// Read-only view of N packed xyz float triples (an N×3 float32 array). No ownership.
struct PointsView {
  const float* data = nullptr;
  std::size_t size = 0;  ///< number of points (rows), not floats
  Vec3 operator[](std::size_t i) const {
    return {data[3 * i], data[3 * i + 1], data[3 * i + 2]};
  }
};

// === Proxies
/// Sphere: centre and radius (radius ≥ 0).
struct Sphere {
  Vec3 center;
  float radius = 0;
};

/// Ellipsoid { x : |diag(1/r) Qᵀ (x − C)| ≤ 1 }. `axes` holds Q column-major: axes[k] is the
/// k-th unit axis (orthonormal, right-handed), radii[k] its semi-axis length (> 0 after fitting).
struct Ellipsoid {
  Vec3 center;
  Vec3 axes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  Vec3 radii = {0, 0, 0};

  /// Maps a world point into the unit-sphere frame: diag(1/r) Qᵀ (p − C).
  Vec3 to_unit(Vec3 p) const {
    const Vec3 d = p - center;
    return {dot(axes[0], d) / radii.x, dot(axes[1], d) / radii.y, dot(axes[2], d) / radii.z};
  }
  /// Maps a world normal into the unit-sphere frame (inverse transpose), normalised.
  Vec3 normal_to_unit(Vec3 n) const {
    return normalize(Vec3{dot(axes[0], n) * radii.x, dot(axes[1], n) * radii.y,
                          dot(axes[2], n) * radii.z});
  }
  float volume() const { return 4.0f / 3.0f * 3.14159265358979f * radii.x * radii.y * radii.z; }
  /// Whether p is inside, in double with a relative slack `tol` on the squared unit-frame
  /// norm (|x'|² ≤ 1 + tol), so a point on the surface up to float32 round-off counts.
  bool contains(Vec3 p, double tol = 1e-5) const {
    const double d[3] = {double(p.x) - double(center.x), double(p.y) - double(center.y),
                         double(p.z) - double(center.z)};
    double u2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double u = (axes[k].x * d[0] + axes[k].y * d[1] + axes[k].z * d[2]) /
                       double(radii[k]);
      u2 += u * u;
    }
    return u2 <= 1 + tol;
  }
  static Ellipsoid from_sphere(const Sphere& s) {
    Ellipsoid e;
    e.center = s.center;
    e.radii = {s.radius, s.radius, s.radius};
    return e;
  }
};

}  // namespace canopy_ao
