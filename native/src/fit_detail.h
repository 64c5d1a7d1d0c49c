// Canopy AO — small helpers private to the fitters (sphere_fit, ellipsoid_fit, shells).
#pragma once

#include <array>
#include <cstdint>

#include "canopy_ao/geometry.h"

namespace canopy_ao::fit_detail {

using P3 = std::array<double, 3>;

inline P3 to_p3(Vec3 v) { return {double(v.x), double(v.y), double(v.z)}; }

inline double dist2(const P3& a, const P3& b) {
  const double x = a[0] - b[0], y = a[1] - b[1], z = a[2] - b[2];
  return x * x + y * y + z * z;
}

// SplitMix64 (Steele, Lea & Flood 2014): a fixed, portable stream, so a seed gives the same
// shuffle / clusters on every machine (std::shuffle and the std distributions do not).
struct SplitMix64 {
  std::uint64_t s;
  std::uint64_t next() {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  std::uint64_t below(std::uint64_t n) { return next() % n; }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
};

}  // namespace canopy_ao::fit_detail
