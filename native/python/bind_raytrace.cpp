// Canopy AO — Python bindings for the Embree ray-traced AO reference (raytrace.h).
//
// Arrays are checked with the GIL held (arrays.h: dtype, shape, contiguity, finiteness, index
// range), then the BVH build and the tracing run with the GIL released, so other Python
// threads (Blender's UI, a second bake) keep running.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
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

RayTraceOptions options_arg(const py::object& samples, double distance, const py::object& seed,
                            double offset) {
  RayTraceOptions o;
  o.samples = static_cast<int>(int_arg(samples, "samples", 1, kMaxSamples));
  distance_arg(distance);
  if (!std::isfinite(offset) || offset > kMaxLength) {
    throw py::value_error("offset must be finite and <= " + num_str(kMaxLength) +
                          " (< 0 = automatic)");
  }
  o.distance = static_cast<float>(distance);
  o.seed = seed_arg(seed);
  o.offset = static_cast<float>(offset);
  return o;
}

/// The Opacity of opacity_materials int32 (M,), opacity_uvs float32 (M, 3, 2) and
/// opacity_alphas (a sequence: each a float, or a float32 (H, W) texture); `keep` holds the
/// arrays until the build has copied them.
Opacity opacity_arg(const py::object& materials, const py::object& uvs, const py::object& alphas,
                    std::size_t m, std::vector<py::array>* keep) {
  Opacity o;
  if (materials.is_none() && uvs.is_none() && alphas.is_none()) return o;
  if (materials.is_none() || alphas.is_none()) {
    throw py::value_error("give opacity_materials and opacity_alphas together");
  }
  keep->push_back(materials.cast<py::array>());
  const py::array& mat = keep->back();
  require_dtype(mat, "opacity_materials", py::dtype::of<std::int32_t>(), "int32");
  if (mat.ndim() != 1 || static_cast<std::size_t>(mat.shape(0)) != m) {
    throw py::value_error("opacity_materials must be int32 (M,) like triangles' rows, got " +
                          shape_str(mat));
  }
  o.materials = static_cast<const std::int32_t*>(mat.data());
  if (!uvs.is_none()) {
    keep->push_back(uvs.cast<py::array>());
    const py::array& uv = keep->back();
    require_dtype(uv, "opacity_uvs", py::dtype::of<float>(), "float32");
    if (uv.ndim() != 3 || static_cast<std::size_t>(uv.shape(0)) != m || uv.shape(1) != 3 ||
        uv.shape(2) != 2) {
      throw py::value_error("opacity_uvs must be float32 (M, 3, 2), got " + shape_str(uv));
    }
    o.uvs = static_cast<const float*>(uv.data());
  }
  // A texture, checked and kept alive in `keep`.
  const auto texture = [keep](const py::handle h, AlphaMaterial* a) {
    keep->push_back(py::reinterpret_borrow<py::array>(h));
    const py::array& tex = keep->back();
    require_dtype(tex, "opacity_alphas texture", py::dtype::of<float>(), "float32");
    if (tex.ndim() != 2 || tex.shape(0) < 1 || tex.shape(1) < 1) {
      throw py::value_error("an opacity_alphas texture must be float32 (H, W), got " +
                            shape_str(tex));
    }
    a->texture = static_cast<const float*>(tex.data());
    a->height = static_cast<int>(tex.shape(0));
    a->width = static_cast<int>(tex.shape(1));
  };
  for (const py::handle item : alphas) {
    AlphaMaterial a;
    if (py::isinstance<py::array>(item)) {
      texture(item, &a);
    } else if (py::isinstance<py::tuple>(item)) {
      // (texture, srgb, scale, offset, nearest): AlphaMaterial's lookup and transform
      const auto t = py::reinterpret_borrow<py::tuple>(item);
      if (py::len(t) != 5 || !py::isinstance<py::array>(t[0])) {
        throw py::value_error(
            "an opacity_alphas tuple must be (texture, srgb, scale, offset, nearest)");
      }
      texture(t[0], &a);
      a.srgb = t[1].cast<bool>();
      a.scale = t[2].cast<float>();
      a.offset = t[3].cast<float>();
      a.nearest = t[4].cast<bool>();
    } else {
      a.alpha = item.cast<float>();
    }
    o.alphas.push_back(a);
  }
  return o;
}

std::unique_ptr<RayTracer> make_tracer(const py::array& vertices, const py::array& triangles,
                                       const py::object& prototypes = py::none(),
                                       const py::object& instance_prototypes = py::none(),
                                       const py::object& instance_matrices = py::none(),
                                       const py::object& normals = py::none(),
                                       const py::object& polygons = py::none(),
                                       const py::object& opacity_materials = py::none(),
                                       const py::object& opacity_uvs = py::none(),
                                       const py::object& opacity_alphas = py::none(),
                                       const py::object& corner_normals = py::none()) {
  const PointsView v = points_arg(vertices, "vertices", /*allow_empty=*/true);
  std::size_t m = 0;
  const std::int32_t* t = triangles_arg(triangles, "triangles", v.size, &m);
  PointsView vn{nullptr, 0};
  py::array normals_keep;
  if (!normals.is_none()) {
    normals_keep = normals.cast<py::array>();
    vn = points_arg(normals_keep, "normals", /*allow_empty=*/true);
    if (vn.size != v.size) {
      std::ostringstream s;
      s << "normals must have one row per vertex like vertices (" << v.size << ", 3), got "
        << shape_str(normals_keep);
      throw py::value_error(s.str());
    }
  }
  BakeShading shading;
  shading.vertex_normals = vn;
  py::array polygons_keep;
  if (!polygons.is_none()) {
    if (normals.is_none()) {
      throw py::value_error("polygons need normals (they only group corners)");
    }
    polygons_keep = polygons.cast<py::array>();
    require_dtype(polygons_keep, "polygons", py::dtype::of<std::int32_t>(), "int32");
    if (polygons_keep.ndim() != 1 || static_cast<std::size_t>(polygons_keep.shape(0)) != m) {
      throw py::value_error("polygons must be int32 (M,) like triangles' rows, got " +
                            shape_str(polygons_keep));
    }
    shading.polygons = static_cast<const std::int32_t*>(polygons_keep.data());
  }
  py::array corners_keep;
  if (!corner_normals.is_none()) {
    if (normals.is_none()) {
      throw py::value_error("corner_normals need normals (they shade the bake points)");
    }
    corners_keep = corner_normals.cast<py::array>();
    require_dtype(corners_keep, "corner_normals", py::dtype::of<float>(), "float32");
    const bool per_triangle = corners_keep.ndim() == 3 &&
                              static_cast<std::size_t>(corners_keep.shape(0)) == m &&
                              corners_keep.shape(1) == 3 && corners_keep.shape(2) == 3;
    const bool rows = corners_keep.ndim() == 2 &&
                      static_cast<std::size_t>(corners_keep.shape(0)) == 3 * m &&
                      corners_keep.shape(1) == 3;
    if (!per_triangle && !rows) {
      throw py::value_error("corner_normals must be float32 (M, 3, 3) or (3M, 3) like "
                            "triangles' corners, got " + shape_str(corners_keep));
    }
    corners_keep = py::array_t<float, py::array::c_style | py::array::forcecast>(corners_keep);
    shading.corner_normals = static_cast<const float*>(corners_keep.data());
  }
  // Instanced meshes; `keep` holds their arrays until the build has copied them.
  std::vector<Prototype> protos;
  std::vector<py::array> keep;
  std::vector<Instance> placed;
  if (!prototypes.is_none()) {
    for (const py::handle item : prototypes) {
      const auto pair = py::reinterpret_borrow<py::sequence>(item);
      if (py::len(pair) != 2) {
        throw py::value_error("prototypes must be (vertices, triangles) pairs");
      }
      keep.push_back(pair[0].cast<py::array>());
      keep.push_back(pair[1].cast<py::array>());
      const py::array& pv = keep[keep.size() - 2];
      const py::array& pt = keep.back();
      Prototype p;
      p.vertices = points_arg(pv, "prototype vertices", /*allow_empty=*/true);
      p.triangles = triangles_arg(pt, "prototype triangles", p.vertices.size, &p.triangle_count);
      protos.push_back(p);
    }
  }
  if (instance_prototypes.is_none() != instance_matrices.is_none()) {
    throw py::value_error("give instance_prototypes and instance_matrices together");
  }
  if (!instance_prototypes.is_none()) {
    const auto ip = instance_prototypes.cast<py::array>();
    const auto im = instance_matrices.cast<py::array>();
    require_dtype(ip, "instance_prototypes", py::dtype::of<std::int32_t>(), "int32");
    require_dtype(im, "instance_matrices", py::dtype::of<float>(), "float32");
    if (ip.ndim() != 1 || im.ndim() != 3 || im.shape(0) != ip.shape(0) || im.shape(1) != 4 ||
        im.shape(2) != 4) {
      throw py::value_error("instance_prototypes must be int32 (K,) and instance_matrices "
                            "float32 (K, 4, 4), got " + shape_str(ip) + " and " +
                            shape_str(im));
    }
    const auto* idx = static_cast<const std::int32_t*>(ip.data());
    const auto* mat = static_cast<const float*>(im.data());
    placed.resize(static_cast<std::size_t>(ip.shape(0)));
    for (std::size_t k = 0; k < placed.size(); ++k) {
      if (idx[k] < 0) {
        throw py::value_error("instance_prototypes[" + std::to_string(k) + "] is negative");
      }
      placed[k].prototype = static_cast<std::uint32_t>(idx[k]);
      std::copy(mat + 16 * k, mat + 16 * (k + 1), placed[k].matrix);
    }
  }
  const Opacity opacity = opacity_arg(opacity_materials, opacity_uvs, opacity_alphas, m, &keep);
  py::gil_scoped_release release;
  return std::make_unique<RayTracer>(v, t, m, shading, opacity, protos, placed);
}

/// The AO (N,), or (AO, bent normals float32 (N, 3)) when `bent` (raytrace.h, "Bent normals").
py::object trace(const RayTracer& tracer, const py::array& points, const py::array& normals,
                 const RayTraceOptions& o, const py::object& vertex_ids = py::none(),
                 const py::object& triangle_ids = py::none(), bool bent = false) {
  const Receivers r = receivers_arg(points, normals, "points");
  const PointsView p = r.positions, n = r.normals;
  OwnPrimitives own;
  own.vertex_ids = ids_arg(vertex_ids, "vertex_ids", p.size);
  own.triangle_ids = ids_arg(triangle_ids, "triangle_ids", p.size);
  py::array_t<float> out = new_floats(p.size);
  float* dst = out.mutable_data();
  py::array_t<float> dirs;
  float* bent_dst = nullptr;
  if (bent) {
    dirs = py::array_t<float>({static_cast<py::ssize_t>(p.size), static_cast<py::ssize_t>(3)});
    bent_dst = dirs.mutable_data();
  }
  {
    py::gil_scoped_release release;
    tracer.ao(p, n, own, o, dst, bent_dst);
  }
  if (bent) return py::make_tuple(out, dirs);
  return std::move(out);
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
  m.attr("TRACER_RULE") = kTracerRule;
  py::class_<RayTracer>(m, "RayTracer",
                        "An Embree scene of two-sided triangles for ray-traced AO, built once "
                        "(expensive: reuse it for many queries).")
      .def(py::init(&make_tracer), py::arg("vertices"), py::arg("triangles"),
           py::arg("prototypes") = py::none(), py::arg("instance_prototypes") = py::none(),
           py::arg("instance_matrices") = py::none(), py::arg("normals") = py::none(),
           py::arg("polygons") = py::none(), py::arg("opacity_materials") = py::none(),
           py::arg("opacity_uvs") = py::none(), py::arg("opacity_alphas") = py::none(),
           py::arg("corner_normals") = py::none(),
           "RayTracer(vertices, triangles, prototypes=None, instance_prototypes=None, "
           "instance_matrices=None, normals=None, polygons=None, opacity_materials=None, "
           "opacity_uvs=None, opacity_alphas=None, corner_normals=None)\n\n"
           "vertices: float32 (V, 3); triangles: int32 (M, 3), indices in [0, V). M may be 0 "
           "(nothing occludes: AO = 1). Instanced meshes (Embree instances: each prototype's "
           "BVH built once): prototypes, a sequence of (vertices float32 (P, 3), triangles "
           "int32 (Q, 3)); instance_prototypes int32 (K,), the prototype of each instance; "
           "instance_matrices float32 (K, 4, 4), row-major world-from-prototype, affine. "
           "Instances occlude like the own mesh but carry no receivers (vertex_ids and "
           "triangle_ids refer to the own mesh). normals: float32 (V, 3), the mesh's vertex "
           "normals; with them a vertex receiver (vertex_ids) starts where Cycles' own vertex "
           "bake starts it (each corner's bake point, raytrace.h 'Origins'), without them on "
           "the surface a hair from the vertex. polygons: int32 (M,), each triangle's face "
           "(a quad's two triangles share one), so a vertex has one corner per face as in "
           "Blender's bake (needs normals). corner_normals: float32 (M, 3, 3) or (3M, 3), each "
           "triangle corner's own (split) normal, which a bake point's hemisphere and "
           "terminator lift then follow as Cycles' do (flat faces, sharp edges, custom "
           "normals; needs normals). Opacity (raytrace.h, 'Opacity'): opacity_materials "
           "int32 (M,), each triangle's index into opacity_alphas (-1 = opaque); "
           "opacity_alphas, each material's alpha: a float, or a float32 (H, W) texture "
           "(row 0 at v = 0, bilinear, repeat) read at the UVs opacity_uvs float32 (M, 3, 2), "
           "or (texture, srgb, scale, offset, nearest): offset + scale * t, t the value "
           "interpolated (the nearest texel's when nearest) and decoded from sRGB when srgb; "
           "a hit of alpha a stops a ray with probability a. "
           "The data are copied. Releases the GIL while the BVH builds. ValueError on bad "
           "input, CanopyAOError if Embree fails.")
      .def(
          "ao",
          [](const RayTracer& self, const py::array& points, const py::array& normals,
             const py::object& samples, double distance, const py::object& seed,
             double offset, const py::object& vertex_ids, const py::object& triangle_ids,
             const std::string& sampling, bool bent_normals, bool per_corner,
             const py::object& point_samples, int point_group) {
            RayTraceOptions o = options_arg(samples, distance, seed, offset);
            o.sampling = sampling_arg(sampling);
            o.per_corner = per_corner;
            o.point_group = point_group;
            o.point_samples = ids_arg(point_samples, "point_samples",
                                      static_cast<std::size_t>(py::len(points)));
            return trace(self, points, normals, o, vertex_ids, triangle_ids, bent_normals);
          },
          py::arg("points"), py::arg("normals"), py::arg("samples") = 64,
          py::arg("distance") = kInf, py::arg("seed") = 0, py::arg("offset") = -1.0,
          py::arg("vertex_ids") = py::none(), py::arg("triangle_ids") = py::none(),
          py::arg("sampling") = "lattice", py::arg("bent_normals") = false,
          py::arg("per_corner") = true, py::arg("point_samples") = py::none(),
          py::arg("point_group") = 1,
          "ao(points, normals, samples=64, distance=inf, seed=0, offset=-1.0, vertex_ids=None, "
          "triangle_ids=None, sampling='lattice', bent_normals=False, per_corner=True, "
          "point_samples=None, point_group=1) -> "
          "float32 (N,), or (ao, bent) with bent_normals\n\n"
          "Cosine-weighted ambient occlusion, 1 = open sky (Cycles' meaning): the fraction of "
          "`samples` cosine-distributed rays from each point (float32 (N, 3)) over the "
          "hemisphere of its normal (float32 (N, 3), normalised here; a zero normal gives 1) "
          "that hit no triangle closer than `distance` (a hard cut-off, Cycles' AO distance; "
          "inf = unlimited). Stratified directions rotated per point from (its vertex id, or its "
          "row index when it names no vertex; seed): "
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
          "Sobol' per point) or 'independent' (i.i.d. rays, the baseline).\n\n"
          "A vertex at Cycles' bake point (a tracer with normals, vertex_ids given) has one "
          "corner per face using it; per_corner=True casts `samples` rays per corner, as "
          "Cycles' bake samples every corner with its full count (one set of k x samples "
          "directions dealt out to the k corners in turn; at most max(samples, 65536)); False "
          "deals `samples` rays out to the corners.\n\n"
          "point_samples: int32 (N,), each point's own count in place of `samples` (>= 1; "
          "ValueError otherwise).\n\n"
          "point_group: g >= 1 consecutive points (rows of this call) form one receiver, a "
          "texel's anti-aliasing sub-samples: the group casts its `samples` (at least g) from "
          "one set keyed by the group (row // g), dealt out to its points in turn (row % g "
          "takes rays row % g, + g, ...); a point with a vertex id keeps its own.\n\n"
          "bent_normals=True also returns each point's bent normal, float32 (N, 3), world "
          "space: the normalised sum of its unblocked rays' directions (the cosine-weighted "
          "mean unoccluded direction), from the same rays as the AO. Every ray blocked: the "
          "unit normal; a zero normal: (0, 0, 0). Releases the GIL.")
      .def_property_readonly("vertex_count", &RayTracer::vertex_count)
      .def_property_readonly("triangle_count", &RayTracer::triangle_count)
      .def_property_readonly("instance_count", &RayTracer::instance_count)
      .def_property_readonly("has_opacity", &RayTracer::has_opacity,
                             "Whether some triangle is not opaque (opacity_materials).")
      .def_property_readonly("has_vertex_normals", &RayTracer::has_vertex_normals,
                             "Whether vertex receivers start at Cycles' bake point.")
      .def_property_readonly("corners_per_vertex", &RayTracer::corners_per_vertex,
                             "Mean corners per vertex: what per-corner rays multiply a bake of "
                             "every vertex's rays by (1 without vertex normals).")
      .def("vertex_rays", &RayTracer::vertex_rays, py::arg("first"), py::arg("count"),
           py::arg("samples"),
           "The rays a bake of the tracer's vertices [first, first + count) casts at `samples` "
           "per face corner (each vertex at Cycles' bake point): what the cost model counts. "
           "ValueError if the range is not in the mesh or samples < 1.")
      .def(
          "vertex_corners",
          [](const RayTracer& self, std::size_t first, std::size_t count) {
            std::vector<std::int32_t> c = self.vertex_corners(first, count);
            py::array_t<std::int32_t> out(static_cast<py::ssize_t>(c.size()));
            std::copy(c.begin(), c.end(), out.mutable_data());
            return out;
          },
          py::arg("first"), py::arg("count"),
          "int32 (count,): each of the tracer's vertices [first, first + count)'s corner count "
          "(its rays at one sample per corner, vertex_rays(v, 1, 1); at least 1, 1 without "
          "vertex normals). ValueError if the range is not in the mesh.")
      .def_property_readonly("auto_offset", &RayTracer::auto_offset,
                             "The origin offset used when offset < 0, in scene units.")
      .def("__repr__", [](const RayTracer& self) {
        return "<RayTracer " + std::to_string(self.vertex_count()) + " vertices, " +
               std::to_string(self.triangle_count()) + " triangles>";
      });

  m.def(
      "ao_raytrace",
      [](const py::array& vertices, const py::array& triangles, const py::array& points,
         const py::array& normals, const py::object& samples, double distance,
         const py::object& seed) {
        // Cheap settings first: no BVH build for a call that must fail.
        const RayTraceOptions o = options_arg(samples, distance, seed, -1.0);
        receivers_arg(points, normals, "points");
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
