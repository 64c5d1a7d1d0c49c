// Canopy AO — Python bindings for the Embree ray-traced AO reference (raytrace.h).
//
// Arrays are checked with the GIL held (arrays.h: dtype, shape, contiguity, finiteness, index
// range), then the BVH build and the tracing run with the GIL released, so other Python
// threads (Blender's UI, a second bake) keep running.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <sstream>
#include <string>

#include "arrays.h"
#include "canopy_ao/raytrace.h"

namespace canopy_ao::py_bind {

namespace {

RayTraceOptions options_arg(int samples, double distance, long long seed, double offset) {
  if (samples < 1) {
    throw py::value_error("samples must be at least 1, got " + std::to_string(samples));
  }
  distance_arg(distance);
  seed_arg(seed);
  if (!std::isfinite(offset)) {
    throw py::value_error("offset must be finite (< 0 = automatic)");
  }
  RayTraceOptions o;
  o.samples = samples;
  o.distance = static_cast<float>(distance);
  o.seed = static_cast<std::uint32_t>(seed);
  o.offset = static_cast<float>(offset);
  return o;
}

std::unique_ptr<RayTracer> make_tracer(const py::array& vertices, const py::array& triangles) {
  const PointsView v = points_arg(vertices, "vertices", /*allow_empty=*/true);
  std::size_t m = 0;
  const std::int32_t* t = triangles_arg(triangles, "triangles", v.size, &m);
  py::gil_scoped_release release;
  return std::make_unique<RayTracer>(v, t, m);
}

/// An optional int32 (N,) array of own-primitive ids (None → nullptr). Values are range-checked
/// by RayTracer::ao (std::invalid_argument → ValueError).
const std::int32_t* ids_arg(const py::object& ids, const char* name, std::size_t n) {
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

py::array_t<float> trace(const RayTracer& tracer, const py::array& points,
                         const py::array& normals, const RayTraceOptions& o,
                         const py::object& vertex_ids = py::none(),
                         const py::object& triangle_ids = py::none()) {
  const PointsView p = points_arg(points, "points", /*allow_empty=*/true);
  const PointsView n = points_arg(normals, "normals", /*allow_empty=*/true);
  check_same_rows(p, "points", n, "normals");
  OwnPrimitives own;
  own.vertex_ids = ids_arg(vertex_ids, "vertex_ids", p.size);
  own.triangle_ids = ids_arg(triangle_ids, "triangle_ids", p.size);
  py::array_t<float> out = new_floats(p.size);
  float* dst = out.mutable_data();
  {
    py::gil_scoped_release release;
    tracer.ao(p, n, own, o, dst);
  }
  return out;
}

constexpr double kInf = std::numeric_limits<double>::infinity();

Sampling sampling_arg(const std::string& name) {
  if (name == "lattice") return Sampling::kLattice;
  if (name == "sobol") return Sampling::kSobol;
  if (name == "independent") return Sampling::kIndependent;
  throw py::value_error("sampling must be 'lattice', 'sobol' or 'independent', got '" + name +
                        "'");
}

}  // namespace

void bind_raytrace(py::module_& m) {
  py::class_<RayTracer>(m, "RayTracer",
                        "An Embree scene of two-sided triangles for ray-traced AO, built once "
                        "(expensive: reuse it for many queries).")
      .def(py::init(&make_tracer), py::arg("vertices"), py::arg("triangles"),
           "RayTracer(vertices, triangles)\n\n"
           "vertices: float32 (V, 3); triangles: int32 (M, 3), indices in [0, V). M may be 0 "
           "(nothing occludes: AO = 1). The data are copied. Releases the GIL while the BVH "
           "builds. ValueError on bad input, CanopyAOError if Embree fails.")
      .def(
          "ao",
          [](const RayTracer& self, const py::array& points, const py::array& normals,
             int samples, double distance, long long seed, double offset,
             const py::object& vertex_ids, const py::object& triangle_ids,
             const std::string& sampling) {
            RayTraceOptions o = options_arg(samples, distance, seed, offset);
            o.sampling = sampling_arg(sampling);
            return trace(self, points, normals, o, vertex_ids, triangle_ids);
          },
          py::arg("points"), py::arg("normals"), py::arg("samples") = 64,
          py::arg("distance") = kInf, py::arg("seed") = 0, py::arg("offset") = -1.0,
          py::arg("vertex_ids") = py::none(), py::arg("triangle_ids") = py::none(),
          py::arg("sampling") = "lattice",
          "ao(points, normals, samples=64, distance=inf, seed=0, offset=-1.0, vertex_ids=None, "
          "triangle_ids=None, sampling='lattice') -> float32 (N,)\n\n"
          "Cosine-weighted ambient occlusion, 1 = open sky (Cycles' meaning): the fraction of "
          "`samples` cosine-distributed rays from each point (float32 (N, 3)) over the "
          "hemisphere of its normal (float32 (N, 3), normalised here; a zero normal gives 1) "
          "that hit no triangle closer than `distance` (a hard cut-off, Cycles' AO distance; "
          "inf = unlimited). Stratified directions rotated per point from (row index, seed): "
          "deterministic, independent of the thread count. Origins move `offset` along the "
          "normal (< 0 = automatic: 1e-5 of the scene diagonal + 1e-6 of its largest "
          "coordinate; see .auto_offset).\n\n"
          "Receivers on the mesh (as Cycles: a ray skips only what it starts on): vertex_ids, "
          "int32 (N,), the tracer's vertex each point is (-1 = none): every triangle using it "
          "is skipped; triangle_ids, int32 (N,), the triangle each point lies on (a texel's; -1 "
          "= none): that triangle is skipped. Such a point's rays start on its own surface "
          "(a hair inside its own triangle, the vertex's one facing the normal most squarely; "
          "no normal offset unless offset >= 0 is given), so a surface it touches (the ground "
          "under a blade root) still occludes. Ids outside their range: ValueError.\n\n"
          "sampling: 'lattice' (a Fibonacci lattice rotated per point), 'sobol' (Owen-scrambled "
          "Sobol' per point) or 'independent' (i.i.d. rays, the baseline). Releases the GIL.")
      .def_property_readonly("vertex_count", &RayTracer::vertex_count)
      .def_property_readonly("triangle_count", &RayTracer::triangle_count)
      .def_property_readonly("auto_offset", &RayTracer::auto_offset,
                             "The origin offset used when offset < 0, in scene units.")
      .def("__repr__", [](const RayTracer& self) {
        return "<RayTracer " + std::to_string(self.vertex_count()) + " vertices, " +
               std::to_string(self.triangle_count()) + " triangles>";
      });

  m.def(
      "ao_raytrace",
      [](const py::array& vertices, const py::array& triangles, const py::array& points,
         const py::array& normals, int samples, double distance, long long seed) {
        // Cheap settings first: no BVH build for a call that must fail.
        const RayTraceOptions o = options_arg(samples, distance, seed, -1.0);
        const PointsView p = points_arg(points, "points", /*allow_empty=*/true);
        const PointsView n = points_arg(normals, "normals", /*allow_empty=*/true);
        check_same_rows(p, "points", n, "normals");
        const std::unique_ptr<RayTracer> tracer = make_tracer(vertices, triangles);
        return trace(*tracer, points, normals, o);
      },
      py::arg("vertices"), py::arg("triangles"), py::arg("points"), py::arg("normals"),
      py::arg("samples") = 64, py::arg("distance") = kInf, py::arg("seed") = 0,
      "ao_raytrace(vertices, triangles, points, normals, samples=64, distance=inf, seed=0) "
      "-> float32 (N,)\n\n"
      "One-off RayTracer(vertices, triangles).ao(points, normals, ...): builds the scene, "
      "traces, frees it. Keep a RayTracer when calling repeatedly.");
}

}  // namespace canopy_ao::py_bind
