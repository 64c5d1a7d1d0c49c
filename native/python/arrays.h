// Canopy AO — numpy ↔ C++ at the module boundary (pybind11 only; the core never sees this).
//
// Every array argument is checked here, once, with a message that names the argument and says
// what was expected: dtype, shape, C-contiguity, finiteness. Arrays are never copied: the core
// gets raw pointers into numpy's buffer (call with the GIL held, compute without it).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>

#include "canopy_ao/geometry.h"

namespace canopy_ao::py_bind {

namespace py = pybind11;

// Only exact float32 / int32 C-contiguous arrays pass: anything else would mean a silent copy
// (float64 positions from Blender are 40× slower to move, docs/DESIGN.md, 'Facts measured in
// Blender').
using FloatArray = py::array;
using IntArray = py::array;

inline std::string shape_str(const py::array& a) {
  std::ostringstream s;
  s << "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s << (i ? ", " : "") << a.shape(i);
  s << (a.ndim() == 1 ? ",)" : ")");
  return s.str();
}

inline void require_dtype(const py::array& a, const char* name, const py::dtype& want,
                          const char* want_name) {
  if (!a.dtype().is(want)) {
    throw py::value_error(std::string(name) + " must have dtype " + want_name + ", got " +
                          std::string(py::str(a.dtype())) + " (convert with np.ascontiguousarray(" +
                          name + ", dtype=np." + want_name + "))");
  }
  if (!(a.flags() & py::array::c_style)) {
    throw py::value_error(std::string(name) +
                          " must be C-contiguous (use np.ascontiguousarray)");
  }
}

/// Checks an (N, 3) float32 C-contiguous array of finite values; returns a view.
/// allow_empty=false rejects N == 0.
inline PointsView points_arg(const py::array& a, const char* name, bool allow_empty = false,
                             bool check_finite = true) {
  require_dtype(a, name, py::dtype::of<float>(), "float32");
  if (a.ndim() != 2 || a.shape(1) != 3) {
    throw py::value_error(std::string(name) + " must have shape (N, 3), got " + shape_str(a));
  }
  PointsView v{static_cast<const float*>(a.data()), static_cast<std::size_t>(a.shape(0))};
  if (!allow_empty && v.size == 0) throw py::value_error(std::string(name) + " is empty");
  if (check_finite) {
    const std::size_t n = 3 * v.size;
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isfinite(v.data[i])) {
        std::ostringstream s;
        s << name << " has a non-finite value (NaN or inf) at row " << i / 3;
        throw py::value_error(s.str());
      }
    }
  }
  return v;
}

/// Checks a pair of (N, 3) float32 arrays of equal length (receiver positions and normals).
inline void check_same_rows(const PointsView& a, const char* an, const PointsView& b,
                            const char* bn) {
  if (a.size != b.size) {
    std::ostringstream s;
    s << an << " and " << bn << " must have the same number of rows, got " << a.size << " and "
      << b.size;
    throw py::value_error(s.str());
  }
}

/// Checks an (N,) float32 C-contiguous array; returns a pointer (nullptr when N == 0).
inline const float* floats_arg(const py::array& a, const char* name, std::size_t expect_n,
                               bool check_finite = true) {
  require_dtype(a, name, py::dtype::of<float>(), "float32");
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != expect_n) {
    std::ostringstream s;
    s << name << " must have shape (" << expect_n << ",), got " << shape_str(a);
    throw py::value_error(s.str());
  }
  const float* p = static_cast<const float*>(a.data());
  if (check_finite) {
    for (std::size_t i = 0; i < expect_n; ++i) {
      if (!std::isfinite(p[i])) {
        std::ostringstream s;
        s << name << " has a non-finite value (NaN or inf) at index " << i;
        throw py::value_error(s.str());
      }
    }
  }
  return p;
}

/// Checks an (M, 3) int32 triangle array whose indices lie in [0, vertex_count).
inline const std::int32_t* triangles_arg(const py::array& a, const char* name,
                                         std::size_t vertex_count, std::size_t* count) {
  require_dtype(a, name, py::dtype::of<std::int32_t>(), "int32");
  if (a.ndim() != 2 || a.shape(1) != 3) {
    throw py::value_error(std::string(name) + " must have shape (M, 3), got " + shape_str(a));
  }
  const auto* t = static_cast<const std::int32_t*>(a.data());
  *count = static_cast<std::size_t>(a.shape(0));
  for (std::size_t i = 0; i < 3 * *count; ++i) {
    if (t[i] < 0 || static_cast<std::size_t>(t[i]) >= vertex_count) {
      std::ostringstream s;
      s << name << " row " << i / 3 << " has vertex index " << t[i] << ", outside [0, "
        << vertex_count << ")";
      throw py::value_error(s.str());
    }
  }
  return t;
}

/// A new (N,) float32 array for results; fill it with the GIL released.
inline py::array_t<float> new_floats(std::size_t n) {
  return py::array_t<float>(static_cast<py::ssize_t>(n));
}

/// An AO distance: > 0, inf = unlimited (Cycles' meaning: a hard cut-off on ray length).
inline float distance_arg(double distance) {
  if (!(distance > 0)) {
    std::ostringstream s;
    s << "distance must be > 0 (inf = unlimited), got " << distance;
    throw py::value_error(s.str());
  }
  return static_cast<float>(distance);
}

/// A random seed: a non-negative integer below 2**32.
inline std::uint32_t seed_arg(long long seed) {
  if (seed < 0 || seed > 0xffffffffLL) {
    throw py::value_error("seed must be in [0, 2**32), got " + std::to_string(seed));
  }
  return static_cast<std::uint32_t>(seed);
}

inline Vec3 vec3_arg(const py::object& o, const char* name) {
  py::array_t<float, py::array::c_style | py::array::forcecast> a(o);
  if (a.ndim() != 1 || a.shape(0) != 3) {
    throw py::value_error(std::string(name) + " must be 3 numbers, got shape " + shape_str(a));
  }
  Vec3 v{a.at(0), a.at(1), a.at(2)};
  if (!is_finite(v)) throw py::value_error(std::string(name) + " has a non-finite value");
  return v;
}

}  // namespace canopy_ao::py_bind
