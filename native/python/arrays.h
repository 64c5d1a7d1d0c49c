// Canopy AO — numpy ↔ C++ at the module boundary (pybind11 only; the core never sees this).
//
// Every array argument is checked here, once, with a message that names the argument and says
// what was expected: dtype, shape, C-contiguity, finiteness, range. Arrays are never copied
// (the core gets raw pointers into numpy's buffer; call with the GIL held, compute without it),
// except normals with a row far from unit length (normals_arg).
//
// The accepted range (native/python/README.md, "Accepted range"). float32 carries 24 bits, and
// the models square and cube lengths and their ratios: a coordinate |x| <= kMaxCoordinate and
// a positive length in [kMinLength, kMaxLength] keep every such power (up to
// (2·kMaxCoordinate)^4, (kMaxLength/kMinLength)^2) inside float32's normal range, so results
// stay finite. Lengths are otherwise scale-free: a scene works the same at 1e-6 or 1e6 units.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>

#include "canopy_ao/geometry.h"
#include "canopy_ao/grass.h"

namespace canopy_ao::py_bind {

namespace py = pybind11;

// Only exact float32 / int32 C-contiguous arrays pass: anything else would mean a silent copy
// (float64 positions from Blender are 40× slower to move, docs/DESIGN.md, 'Facts measured in
// Blender').
using FloatArray = py::array;
using IntArray = py::array;

/// Largest |coordinate| of any position, vertex, centre or height (scene units).
constexpr double kMaxCoordinate = 1e9;
/// Smallest positive length (radius, blade height, AO distance, near) and the largest.
constexpr double kMinLength = 1e-9;
constexpr double kMaxLength = 1e10;
/// Most rays per receiver a tracer takes (cost is linear in it; 2^16 is far past convergence).
constexpr long long kMaxSamples = 1 << 16;

inline std::string num_str(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

/// A coordinate (a height, one component of a centre): finite, |v| <= kMaxCoordinate.
inline float coordinate_arg(double v, const char* name) {
  if (!(std::fabs(v) <= kMaxCoordinate)) {
    throw py::value_error(std::string(name) + " must be a finite number within +-" +
                          num_str(kMaxCoordinate) + " (the accepted coordinate range), got " +
                          num_str(v));
  }
  return static_cast<float>(v);
}

/// A positive length in [kMinLength, kMaxLength] (zero_ok: 0 is accepted too).
inline float length_arg(double v, const char* name, bool zero_ok = false) {
  if (zero_ok && v == 0) return 0.0f;
  if (!(v >= kMinLength && v <= kMaxLength)) {
    throw py::value_error(std::string(name) + " must be a finite length in [" +
                          num_str(kMinLength) + ", " + num_str(kMaxLength) + "]" +
                          (zero_ok ? " or 0" : "") + ", got " + num_str(v));
  }
  return static_cast<float>(v);
}

/// Largest τ: AO at a shell's centre exp(−1e4) is 0 in any float, and beyond it the models'
/// products (τ · cap volume, τ · chord) would leave float32's range.
constexpr double kMaxTau = 1e4;

/// An optical depth τ in [0, kMaxTau].
inline float tau_arg(double tau) {
  if (!(tau >= 0 && tau <= kMaxTau)) {
    throw py::value_error("tau must be a finite number in [0, " + num_str(kMaxTau) + "], got " +
                          num_str(tau));
  }
  return static_cast<float>(tau);
}

/// An integer (a Python int, or anything with __index__: numpy integers) in [lo, hi]. Anything
/// else, or out of range (also beyond 64 bits), is a ValueError with the range, not pybind's
/// TypeError.
inline long long int_arg(const py::object& v, const char* name, long long lo, long long hi) {
  PyObject* index = PyNumber_Index(v.ptr());
  if (index == nullptr) {
    PyErr_Clear();
    throw py::value_error(std::string(name) + " must be an integer in [" + std::to_string(lo) +
                          ", " + std::to_string(hi) + "], got " + std::string(py::repr(v)));
  }
  int overflow = 0;
  const long long x = PyLong_AsLongLongAndOverflow(index, &overflow);
  Py_DECREF(index);
  if (overflow == 0 && x == -1 && PyErr_Occurred()) throw py::error_already_set();
  if (overflow != 0 || x < lo || x > hi) {
    throw py::value_error(std::string(name) + " must be an integer in [" + std::to_string(lo) +
                          ", " + std::to_string(hi) + "], got " + std::string(py::repr(v)));
  }
  return x;
}
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

inline PointsView rows3_arg(const py::array& a, const char* name, bool allow_empty) {
  require_dtype(a, name, py::dtype::of<float>(), "float32");
  if (a.ndim() != 2 || a.shape(1) != 3) {
    throw py::value_error(std::string(name) + " must have shape (N, 3), got " + shape_str(a));
  }
  PointsView v{static_cast<const float*>(a.data()), static_cast<std::size_t>(a.shape(0))};
  if (!allow_empty && v.size == 0) throw py::value_error(std::string(name) + " is empty");
  return v;
}

/// Floats checked per branch-free block by the array checks below.
constexpr std::size_t kCheckBlock = 3 * 1024;

/// |x| as the bits of a non-negative float: ordered as the values are (+0 < denormals < normals
/// < inf < NaN), so range and finiteness checks are integer compares, which vectorise.
inline std::uint32_t abs_bits(float x) {
  std::uint32_t u;
  std::memcpy(&u, &x, sizeof u);
  return u & 0x7fffffffu;
}
constexpr std::uint32_t kInfBits = 0x7f800000u;

inline void throw_bad_value(const char* name, float x, std::size_t row, double limit) {
  std::ostringstream s;
  if (!std::isfinite(x)) {
    s << name << " has a non-finite value (NaN or inf) at row " << row;
  } else {
    s << name << " has the value " << x << " at row " << row << ", outside +-" << limit
      << " (the accepted coordinate range)";
  }
  throw py::value_error(s.str());
}

/// Checks an (N, 3) float32 C-contiguous array of finite coordinates within +-kMaxCoordinate;
/// returns a view. allow_empty=false rejects N == 0.
inline PointsView points_arg(const py::array& a, const char* name, bool allow_empty = false) {
  const PointsView v = rows3_arg(a, name, allow_empty);
  const float limit = static_cast<float>(kMaxCoordinate);
  const std::size_t m = 3 * v.size;
  // Branch-free over a block (it vectorises; NaN fails the comparison); the first bad value is
  // looked for only in a block that has one. Every call checks every point, so this matters.
  for (std::size_t b = 0; b < m; b += kCheckBlock) {
    const std::size_t e = std::min(m, b + kCheckBlock);
    const std::uint32_t top = abs_bits(limit);
    std::uint32_t bad = 0;
    for (std::size_t i = b; i < e; ++i) bad |= abs_bits(v.data[i]) > top;  // NaN too
    if (!bad) continue;
    for (std::size_t i = b; i < e; ++i)
      if (!(std::fabs(v.data[i]) <= limit)) throw_bad_value(name, v.data[i], i / 3, kMaxCoordinate);
  }
  return v;
}

/// Normals: (N, 3) float32, finite, any length (zero rows = no normal, as each model says).
/// The core squares them in float32, so a row whose largest component lies outside
/// [2^-10, 2^10] (or that is tiny but non-zero) would overflow or vanish: when any row does,
/// every row is rescaled to unit length in a private copy (in double), zero rows stay zero.
struct NormalsArg {
  PointsView view;
  py::array keep;  ///< owns the rescaled copy, if one was made
};

inline NormalsArg normals_arg(const py::array& a, const char* name) {
  NormalsArg r{rows3_arg(a, name, /*allow_empty=*/true), py::array()};
  const float* d = r.view.data;
  std::uint32_t rescale = 0;
  const std::uint32_t lo = abs_bits(0x1p-10f), hi = abs_bits(0x1p10f);
  const std::size_t rows = r.view.size, block = kCheckBlock / 3;
  for (std::size_t b = 0; b < rows; b += block) {  // branch-free per block, as points_arg
    const std::size_t e = std::min(rows, b + block);
    std::uint32_t bad = 0;
    for (std::size_t i = b; i < e; ++i) {
      const std::uint32_t x = abs_bits(d[3 * i]), y = abs_bits(d[3 * i + 1]),
                          z = abs_bits(d[3 * i + 2]);
      const std::uint32_t m = std::max(x, std::max(y, z));
      bad |= m >= kInfBits;  // inf or NaN in the row
      rescale |= (m != 0) & ((m < lo) | (m > hi));
    }
    if (!bad) continue;
    for (std::size_t i = b; i < e; ++i)
      for (int k = 0; k < 3; ++k)
        if (!std::isfinite(d[3 * i + k])) throw_bad_value(name, d[3 * i + k], i, 0);
  }
  if (!rescale) return r;
  py::array_t<float> copy({static_cast<py::ssize_t>(r.view.size), py::ssize_t{3}});
  float* c = copy.mutable_data();
  for (std::size_t i = 0; i < r.view.size; ++i) {
    double m = 0;
    for (int k = 0; k < 3; ++k) m = std::max(m, std::fabs(double(d[3 * i + k])));
    double v[3], l2 = 0;
    for (int k = 0; k < 3; ++k) {
      v[k] = m > 0 ? d[3 * i + k] / m : 0.0;  // largest component ±1: no overflow, no underflow
      l2 += v[k] * v[k];
    }
    for (int k = 0; k < 3; ++k) c[3 * i + k] = static_cast<float>(m > 0 ? v[k] / std::sqrt(l2) : 0.0);
  }
  r.view = PointsView{c, r.view.size};
  r.keep = std::move(copy);
  return r;
}

/// Receivers: positions (coordinates) and normals (any length) with the same number of rows.
struct Receivers {
  PointsView positions, normals;
  py::array keep;
};

inline Receivers receivers_arg(const py::array& positions, const py::array& normals,
                               const char* positions_name = "positions") {
  const PointsView p = points_arg(positions, positions_name, /*allow_empty=*/true);
  NormalsArg n = normals_arg(normals, "normals");
  if (p.size != n.view.size) {
    std::ostringstream s;
    s << positions_name << " and normals must have the same number of rows, got " << p.size
      << " and " << n.view.size;
    throw py::value_error(s.str());
  }
  return Receivers{p, n.view, std::move(n.keep)};
}

/// An optional int32 (N,) array of own-primitive ids (None → nullptr). Values are range-checked
/// by RayTracer::ao (std::invalid_argument → ValueError).
inline const std::int32_t* ids_arg(const py::object& ids, const char* name, std::size_t n) {
  if (ids.is_none()) return nullptr;
  if (!py::isinstance<py::array>(ids)) {
    throw py::value_error(std::string(name) + " must be None or an int32 numpy array");
  }
  const auto a = py::reinterpret_borrow<py::array>(ids);
  require_dtype(a, name, py::dtype::of<std::int32_t>(), "int32");
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != n) {
    std::ostringstream s;
    s << name << " must have shape (" << n << ",) like points, got " << shape_str(a);
    throw py::value_error(s.str());
  }
  return static_cast<const std::int32_t*>(a.data());
}

/// A grass field's blade layer (grass.h, GrassOptions::layer) from None or a float32 (rows,
/// cols) array, rows, cols >= 2; values are checked by ao_grass (std::invalid_argument).
inline void blade_layer_arg(const py::object& layer, GrassOptions* o) {
  o->layer.clear();
  o->layer_rows = o->layer_cols = 0;
  if (layer.is_none()) return;
  if (!py::isinstance<py::array>(layer)) {
    throw py::value_error("layer must be None or a float32 numpy array (rows, cols)");
  }
  const auto a = py::reinterpret_borrow<py::array>(layer);
  require_dtype(a, "layer", py::dtype::of<float>(), "float32");
  if (a.ndim() != 2 || a.shape(0) < 2 || a.shape(1) < 2) {
    throw py::value_error("layer must have shape (rows, cols) with rows, cols >= 2, got " +
                          shape_str(a));
  }
  const float* v = static_cast<const float*>(a.data());
  o->layer.assign(v, v + a.shape(0) * a.shape(1));
  o->layer_rows = static_cast<int>(a.shape(0));
  o->layer_cols = static_cast<int>(a.shape(1));
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

/// Runs fn(out) without the GIL on a new float32 array (N,), or (N, columns) when columns > 0,
/// and returns the array.
template <class Fn>
py::array_t<float> compute(std::size_t n, Fn&& fn, py::ssize_t columns = 0) {
  py::array_t<float> out = columns > 0
                               ? py::array_t<float>({static_cast<py::ssize_t>(n), columns})
                               : new_floats(n);
  float* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    fn(o);
  }
  return out;
}

/// fn()'s result, computed without the GIL (fn must touch no Python object).
template <class Fn>
auto without_gil(Fn&& fn) {
  py::gil_scoped_release release;
  return fn();
}

/// An AO distance: >= kMinLength, inf = unlimited (Cycles' meaning: a hard cut-off on ray
/// length); anything beyond kMaxLength is as good as unlimited and is passed as given.
inline float distance_arg(double distance, const char* name = "distance") {
  if (!(distance >= kMinLength)) {
    std::ostringstream s;
    s << name << " must be >= " << kMinLength << " (inf = unlimited), got " << distance;
    throw py::value_error(s.str());
  }
  return static_cast<float>(distance);
}

/// A random seed: a non-negative integer below 2**32.
inline std::uint32_t seed_arg(const py::object& seed) {
  return static_cast<std::uint32_t>(int_arg(seed, "seed", 0, 0xffffffffLL));
}

/// 3 finite numbers (any sequence or array numpy converts). Taken in double, so a value
/// beyond float32's range is refused rather than turned into inf.
inline Vec3 vec3_arg(const py::object& o, const char* name) {
  py::array_t<double, py::array::c_style | py::array::forcecast> a;
  try {
    a = py::array_t<double, py::array::c_style | py::array::forcecast>(o);
  } catch (const py::error_already_set&) {
    throw py::value_error(std::string(name) + " must be 3 numbers, got " +
                          std::string(py::repr(o)));
  }
  if (a.ndim() != 1 || a.shape(0) != 3) {
    throw py::value_error(std::string(name) + " must be 3 numbers, got shape " + shape_str(a));
  }
  for (int k = 0; k < 3; ++k) {
    if (!(std::fabs(a.at(k)) <= 3.4e38)) {
      throw py::value_error(std::string(name) + " has a non-finite value");
    }
  }
  return Vec3{static_cast<float>(a.at(0)), static_cast<float>(a.at(1)),
              static_cast<float>(a.at(2))};
}

/// A point: 3 coordinates within +-kMaxCoordinate.
inline Vec3 point3_arg(const py::object& o, const char* name) {
  const Vec3 v = vec3_arg(o, name);
  for (int k = 0; k < 3; ++k) coordinate_arg(v[k], name);
  return v;
}

/// A direction: 3 finite numbers, not all zero (any length; normalised by the core).
inline Vec3 direction_arg(const py::object& o, const char* name) {
  const Vec3 v = vec3_arg(o, name);
  if (v.x == 0 && v.y == 0 && v.z == 0) {
    throw py::value_error(std::string(name) + " must not be the zero vector");
  }
  return v;
}

}  // namespace canopy_ao::py_bind
