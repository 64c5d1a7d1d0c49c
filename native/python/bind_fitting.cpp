// Canopy AO — Python bindings for the proxy types (Sphere, Ellipsoid) and the fitting functions.
//
// The types are registered here, first (module.cpp calls bind_fitting before the other areas),
// so every other binding can take `const Sphere&` / `const Ellipsoid&` / `std::vector<Ellipsoid>`
// arguments directly.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "arrays.h"
#include "canopy_ao/ellipsoid_fit.h"
#include "canopy_ao/geometry.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/shells.h"
#include "canopy_ao/sphere_fit.h"

namespace canopy_ao::py_bind {

namespace {

py::array_t<float> vec3_array(Vec3 v) {
  py::array_t<float> a(3);
  auto r = a.mutable_unchecked<1>();
  for (int i = 0; i < 3; ++i) r(i) = v[i];
  return a;
}

// A sphere's radius: 0 (a point; the models refuse it) or a length in the accepted range.
float radius_arg(double r, const char* name) { return length_arg(r, name, /*zero_ok=*/true); }

Vec3 radii_arg(const py::object& o) {
  const Vec3 r = vec3_arg(o, "radii");
  for (int k = 0; k < 3; ++k) length_arg(r[k], "radii");
  return r;
}

// Axes from a (3, 3) array whose columns are the unit axes. Accepted if orthonormal within
// 1e-3 (float64 rotation matrices, float32 round-off); then re-orthonormalised exactly
// (Gram-Schmidt in double) and made right-handed by flipping the third axis, which leaves the
// ellipsoid's shape unchanged (it is symmetric about every axis).
void axes_arg(const py::object& o, Vec3 axes[3]) {
  py::array_t<double, py::array::c_style | py::array::forcecast> a(o);
  if (a.ndim() != 2 || a.shape(0) != 3 || a.shape(1) != 3) {
    throw py::value_error("axes must have shape (3, 3) (columns = unit axes), got " +
                          shape_str(a));
  }
  double q[3][3];  // q[k] = k-th axis (column k)
  for (int k = 0; k < 3; ++k)
    for (int i = 0; i < 3; ++i) {
      q[k][i] = a.at(i, k);
      if (!std::isfinite(q[k][i])) throw py::value_error("axes has a non-finite value");
    }
  for (int k = 0; k < 3; ++k)
    for (int l = 0; l < 3; ++l) {
      const double d = q[k][0] * q[l][0] + q[k][1] * q[l][1] + q[k][2] * q[l][2];
      if (std::abs(d - (k == l ? 1.0 : 0.0)) > 1e-3) {
        throw py::value_error(
            "axes must be orthonormal (columns = unit axes, within 1e-3); got a column dot "
            "product of " +
            std::to_string(d) + " for columns " + std::to_string(k) + ", " + std::to_string(l));
      }
    }
  for (int k = 0; k < 3; ++k) {
    for (int l = 0; l < k; ++l) {
      const double d = q[k][0] * q[l][0] + q[k][1] * q[l][1] + q[k][2] * q[l][2];
      for (int i = 0; i < 3; ++i) q[k][i] -= d * q[l][i];
    }
    const double n = std::sqrt(q[k][0] * q[k][0] + q[k][1] * q[k][1] + q[k][2] * q[k][2]);
    for (int i = 0; i < 3; ++i) q[k][i] /= n;
  }
  const double det = q[0][0] * (q[1][1] * q[2][2] - q[1][2] * q[2][1]) -
                     q[0][1] * (q[1][0] * q[2][2] - q[1][2] * q[2][0]) +
                     q[0][2] * (q[1][0] * q[2][1] - q[1][1] * q[2][0]);
  if (det < 0)
    for (int i = 0; i < 3; ++i) q[2][i] = 0.0 - q[2][i];  // 0 - x: no -0 in output
  for (int k = 0; k < 3; ++k)
    axes[k] = Vec3{static_cast<float>(q[k][0]), static_cast<float>(q[k][1]),
                   static_cast<float>(q[k][2])};
}

py::array_t<float> axes_array(const Ellipsoid& e) {
  py::array_t<float> a({3, 3});
  auto r = a.mutable_unchecked<2>();
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) r(i, k) = e.axes[k][i];
  return a;
}

Ellipsoid make_ellipsoid(const py::object& center, const py::object& axes,
                         const py::object& radii) {
  Ellipsoid e;
  e.center = point3_arg(center, "center");
  axes_arg(axes, e.axes);
  e.radii = radii_arg(radii);
  return e;
}

// Containment in double with a relative slack of `tol` on the squared unit-frame norm, so a
// point on the surface (up to float32 round-off) counts as inside.
// `inside(x, tol)` is a template argument, so the test inlines into the loop.
template <class Inside>
py::array_t<bool> contains_points(const py::array& points, double tol, const Inside& inside) {
  const PointsView p = points_arg(points, "points", /*allow_empty=*/true);
  if (!std::isfinite(tol) || tol < 0) throw py::value_error("tol must be finite and >= 0");
  py::array_t<bool> out(static_cast<py::ssize_t>(p.size));
  bool* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    // Points are independent: parallel blocks, the same answer on any thread count.
    parallel_for_blocks(p.size, 1 << 15, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) o[i] = inside(p.data + 3 * i, tol);
    });
  }
  return out;
}

bool sphere_inside(const void* shape, const float* x, double tol) {
  const auto& s = *static_cast<const Sphere*>(shape);
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double d = double(x[k]) - double(s.center[k]);
    d2 += d * d;
  }
  const double r = s.radius;
  return d2 <= r * r * (1 + tol) + 1e-30;
}

bool ellipsoid_inside(const void* shape, const float* x, double tol) {
  return static_cast<const Ellipsoid*>(shape)->contains(Vec3{x[0], x[1], x[2]}, tol);
}

std::string fmt(Vec3 v) {
  std::ostringstream s;
  s << "(" << v.x << ", " << v.y << ", " << v.z << ")";
  return s.str();
}

EllipsoidMethod method_arg(const std::string& m) {
  if (m == "auto") return EllipsoidMethod::Auto;
  if (m == "khachiyan") return EllipsoidMethod::Khachiyan;
  if (m == "pca") return EllipsoidMethod::Pca;
  throw py::value_error("method must be 'auto', 'khachiyan' or 'pca', got '" + m + "'");
}

ShellKind kind_arg(const std::string& k) {
  if (k == "ellipsoid") return ShellKind::Ellipsoid;
  if (k == "sphere") return ShellKind::Sphere;
  throw py::value_error("kind must be 'ellipsoid' or 'sphere', got '" + k + "'");
}

EllipsoidFitOptions ellipsoid_options(double trim, const std::string& method, double tolerance,
                                      const py::object& max_points_arg,
                                      double min_radius_ratio) {
  const long long max_points = int_arg(max_points_arg, "max_points", 4, 1LL << 40);
  EllipsoidFitOptions o;
  o.trim = trim;
  o.method = method_arg(method);
  o.tolerance = tolerance;
  o.max_points = static_cast<std::size_t>(max_points);
  o.min_radius_ratio = min_radius_ratio;
  return o;
}

}  // namespace

void bind_fitting(py::module_& m) {
  // === Types
  py::class_<Sphere>(m, "Sphere",
                     "A sphere proxy: .center (3,) float32, .radius float (>= 0).")
      .def(py::init([](const py::object& center, double radius) {
             Sphere s;
             s.center = point3_arg(center, "center");
             s.radius = radius_arg(radius, "radius");
             return s;
           }),
           py::arg("center"), py::arg("radius"),
           "Sphere(center, radius): center 3 coordinates within +-1e9, radius 0 or in [1e-9, "
           "1e10] (native/python/README.md, 'Accepted range').")
      .def_property(
          "center", [](const Sphere& s) { return vec3_array(s.center); },
          [](Sphere& s, const py::object& c) { s.center = point3_arg(c, "center"); },
          "Centre, a new (3,) float32 array (assign 3 numbers to change it).")
      .def_property(
          "radius", [](const Sphere& s) { return double(s.radius); },
          [](Sphere& s, double r) { s.radius = radius_arg(r, "radius"); }, "Radius (>= 0).")
      .def(
          "contains",
          [](const Sphere& s, const py::array& points, double tol) {
            return contains_points(points, tol, [&s](const float* x, double t) {
              return sphere_inside(&s, x, t);
            });
          },
          py::arg("points"), py::arg("tol") = 1e-5,
          "contains(points, tol=1e-5) -> bool (N,): |p - center|^2 <= radius^2 (1 + tol); "
          "points float32 (N, 3).")
      .def("__repr__",
           [](const Sphere& s) {
             std::ostringstream o;
             o << "Sphere(center=" << fmt(s.center) << ", radius=" << s.radius << ")";
             return o.str();
           })
      .def(py::pickle(
          [](const Sphere& s) { return py::make_tuple(vec3_array(s.center), double(s.radius)); },
          [](const py::tuple& t) {
            if (t.size() != 2) throw py::value_error("bad Sphere pickle state");
            Sphere s;
            s.center = point3_arg(t[0], "center");
            s.radius = radius_arg(t[1].cast<double>(), "radius");
            return s;
          }));

  py::class_<Ellipsoid>(
      m, "Ellipsoid",
      "An ellipsoid proxy { x : |diag(1/radii) axes^T (x - center)| <= 1 }: .center (3,), "
      ".axes (3, 3) whose columns are the unit axes (orthonormal, right-handed), .radii (3,) "
      "> 0. All float32.")
      .def(py::init(&make_ellipsoid), py::arg("center"), py::arg("axes"), py::arg("radii"),
           "Ellipsoid(center, axes, radii): axes (3, 3), columns = unit axes, orthonormal "
           "within 1e-3 (re-orthonormalised; a left-handed set has its third axis flipped, "
           "which leaves the shape unchanged); radii 3 numbers > 0.")
      .def_static(
          "from_sphere",
          [](const Sphere& s) {
            length_arg(s.radius, "sphere radius");  // an Ellipsoid's radii are > 0
            return Ellipsoid::from_sphere(s);
          },
          py::arg("sphere"),
          "The ellipsoid equal to a sphere (identity axes, equal radii); a radius-0 sphere is a "
          "ValueError.")
      .def_property(
          "center", [](const Ellipsoid& e) { return vec3_array(e.center); },
          [](Ellipsoid& e, const py::object& c) { e.center = point3_arg(c, "center"); },
          "Centre, a new (3,) float32 array.")
      .def_property(
          "axes", [](const Ellipsoid& e) { return axes_array(e); },
          [](Ellipsoid& e, const py::object& a) { axes_arg(a, e.axes); },
          "(3, 3) float32, columns = unit axes (a new array each time).")
      .def_property(
          "radii", [](const Ellipsoid& e) { return vec3_array(e.radii); },
          [](Ellipsoid& e, const py::object& r) { e.radii = radii_arg(r); },
          "Semi-axis lengths along each axis, (3,) float32, > 0.")
      .def("volume", &Ellipsoid::volume, "4/3 pi a b c.")
      .def(
          "contains",
          [](const Ellipsoid& e, const py::array& points, double tol) {
            return contains_points(points, tol, [&e](const float* x, double t) {
              return ellipsoid_inside(&e, x, t);
            });
          },
          py::arg("points"), py::arg("tol") = 1e-5,
          "contains(points, tol=1e-5) -> bool (N,): |diag(1/r) Q^T (p - c)|^2 <= 1 + tol; "
          "points float32 (N, 3).")
      .def("__repr__",
           [](const Ellipsoid& e) {
             std::ostringstream o;
             o << "Ellipsoid(center=" << fmt(e.center) << ", axes=[" << fmt(e.axes[0]) << ", "
               << fmt(e.axes[1]) << ", " << fmt(e.axes[2]) << "], radii=" << fmt(e.radii)
               << ")";
             return o.str();
           })
      .def(py::pickle(
          [](const Ellipsoid& e) {
            return py::make_tuple(vec3_array(e.center), axes_array(e), vec3_array(e.radii));
          },
          [](const py::tuple& t) {
            if (t.size() != 3) throw py::value_error("bad Ellipsoid pickle state");
            return make_ellipsoid(t[0], t[1], t[2]);
          }));

  // === Fitting (std::invalid_argument from the core becomes ValueError)
  m.def(
      "fit_sphere",
      [](const py::array& points, double trim) {
        const PointsView p = points_arg(points, "points");
        py::gil_scoped_release release;
        return fit_min_sphere(p, trim);
      },
      py::arg("points"), py::arg("trim") = 0.0,
      "fit_sphere(points, trim=0.0) -> Sphere\n\n"
      "Exact minimum enclosing sphere (Gaertner's Miniball) of points, float32 (N, 3), N >= 1, "
      "finite. It contains every point: the radius is measured from the float centre and "
      "inflated by a relative 1e-6, and is at least 1e-6 * (|centre| + 1) (a single point).\n"
      "trim in [0, 0.5): that fraction of points farthest from the coordinate-wise median is "
      "ignored (outlier branches); the sphere then contains the kept points only.");

  py::class_<EllipsoidWarmStart>(
      m, "EllipsoidWarmStart",
      "What an ellipsoid fit leaves for the next fit of the same points moved a little (its "
      "Khachiyan support and weights); pass it as fit_ellipsoid(..., warm=state).")
      .def(py::init<>())
      .def_property_readonly("support",
                             [](const EllipsoidWarmStart& w) { return w.active.size(); },
                             "Number of support points kept (0: none yet, a fresh fit).");

  m.def(
      "fit_ellipsoid",
      [](const py::array& points, double trim, const std::string& method, double tolerance,
         const py::object& max_points, double min_radius_ratio, EllipsoidWarmStart* warm) {
        const PointsView p = points_arg(points, "points");
        const EllipsoidFitOptions o =
            ellipsoid_options(trim, method, tolerance, max_points, min_radius_ratio);
        py::gil_scoped_release release;
        return fit_min_ellipsoid(p, o, nullptr, warm);
      },
      py::arg("points"), py::arg("trim") = 0.0, py::arg("method") = "auto",
      py::arg("tolerance") = 1e-3, py::arg("max_points") = 20000,
      py::arg("min_radius_ratio") = 1e-2, py::arg("warm") = nullptr,
      "fit_ellipsoid(points, trim=0.0, method='auto', tolerance=1e-3, max_points=20000, "
      "min_radius_ratio=0.01, warm=None) -> Ellipsoid\n\n"
      "warm: an EllipsoidWarmStart, read when it is a fit of as many points (Khachiyan then "
      "starts from its support and weights: the same points moved a little, a live frame) and "
      "refilled; the result is within the tolerance of a fresh fit's.\n"
      "Minimum-volume enclosing ellipsoid of points, float32 (N, 3), N >= 1, finite.\n"
      "method: 'khachiyan' (Khachiyan/Todd-Yildirim on at most max_points points, then scaled "
      "to contain every point; volume within (1 + tolerance)^(3/2) of optimal on that sample), "
      "'pca' (covariance axes, box aspect, scaled to contain all), 'auto' (khachiyan, or pca "
      "if smaller).\n"
      "Flat, line-like or single-point input: axes thinner than 1e-3 of the widest are fitted "
      "in fewer dimensions; every radius is then at least min_radius_ratio x the largest and "
      "at least 1e-6 * (|centre| + 1). Axes (columns) sorted by decreasing radius, "
      "orthonormal, right-handed.\n"
      "trim in [0, 0.5): that fraction of points with the largest robust Mahalanobis distance "
      "is ignored.");

  m.def(
      "fit_shells",
      [](const py::array& points, const py::object& k, const std::string& kind, double trim,
         const py::object& seed, const py::object& max_iterations) {
        const PointsView p = points_arg(points, "points");
        ShellFitOptions o;
        o.k = static_cast<int>(int_arg(k, "k", 1, 1 << 30));
        o.kind = kind_arg(kind);
        o.trim = trim;
        o.seed = static_cast<std::uint64_t>(int_arg(seed, "seed", 0, INT64_MAX));
        o.max_iterations = static_cast<int>(int_arg(max_iterations, "max_iterations", 1, 1 << 20));
        ShellFit f;
        {
          py::gil_scoped_release release;
          f = fit_shells(p, o);
        }
        py::array_t<std::int32_t> labels(static_cast<py::ssize_t>(f.labels.size()));
        std::copy(f.labels.begin(), f.labels.end(), labels.mutable_data());
        return py::make_tuple(py::cast(f.shells), labels);
      },
      py::arg("points"), py::arg("k"), py::arg("kind") = "ellipsoid", py::arg("trim") = 0.0,
      py::arg("seed") = 0, py::arg("max_iterations") = 100,
      "fit_shells(points, k, kind='ellipsoid', trim=0.0, seed=0, max_iterations=100) -> "
      "(list[Ellipsoid], labels)\n\n"
      "Clusters points, float32 (N, 3), with seeded k-means++ and Lloyd iterations and fits "
      "one shell per cluster (kind 'ellipsoid': fit_ellipsoid; 'sphere': fit_sphere as an "
      "Ellipsoid), trim applied per cluster. labels: int32 (N,), the shell of each point. "
      "Empty clusters are dropped, so fewer than k shells come back when there are fewer "
      "distinct points than k. Same seed, same result, whatever the thread count.");
}

}  // namespace canopy_ao::py_bind
