// Canopy AO — Python bindings for the uniform-medium expectation (medium_table.h) and the
// leaf-density grid (density_grid.h). Arrays are checked with the GIL held (arrays.h), the
// work runs with it released.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "arrays.h"
#include "canopy_ao/density_grid.h"
#include "canopy_ao/medium_table.h"
#include "canopy_ao/raytrace.h"

namespace canopy_ao::py_bind {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// tau: one number for every shell, or a sequence with one per shell.
std::vector<float> taus_arg(const py::object& o, std::size_t shells) {
  std::vector<float> t;
  if (py::isinstance<py::float_>(o) || py::isinstance<py::int_>(o)) {
    t.push_back(tau_arg(o.cast<double>()));
    return t;
  }
  py::array_t<double, py::array::c_style | py::array::forcecast> a(o);
  if (a.ndim() == 0) {  // a numpy scalar
    t.push_back(tau_arg(*a.data()));
    return t;
  }
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != shells) {
    throw py::value_error("tau must be a number or a sequence of " + std::to_string(shells) +
                          " numbers (one per shell), got shape " + shape_str(a));
  }
  for (py::ssize_t i = 0; i < a.shape(0); ++i) t.push_back(tau_arg(a.at(i)));
  return t;
}

MediumCombine combine_arg(const std::string& s) {
  if (s == "product") return MediumCombine::Product;
  if (s == "nearest") return MediumCombine::Nearest;
  throw py::value_error("combine must be \"product\" or \"nearest\", got \"" + s + "\"");
}

// Receivers → result array, computed by `f(p, n, out)` with the GIL released.
template <class F>
py::array_t<float> per_point(const py::array& positions, const py::array& normals, F&& f,
                             const char* positions_name = "positions") {
  const Receivers r = receivers_arg(positions, normals, positions_name);
  py::array_t<float> out = new_floats(r.positions.size);
  float* dst = out.mutable_data();
  {
    py::gil_scoped_release release;
    f(r.positions, r.normals, dst);
  }
  return out;
}

std::unique_ptr<DensityGrid> make_grid(const py::array& vertices, const py::array& triangles,
                                       const py::object& resolution_arg) {
  const int resolution = static_cast<int>(int_arg(resolution_arg, "resolution", 1, 1024));
  const PointsView v = points_arg(vertices, "vertices", /*allow_empty=*/true);
  std::size_t m = 0;
  const std::int32_t* t = triangles_arg(triangles, "triangles", v.size, &m);
  DensityGridOptions o;
  o.resolution = resolution;
  py::gil_scoped_release release;
  return std::make_unique<DensityGrid>(v, t, m, o);
}

DensityAOOptions grid_options(const py::object& directions_arg, double distance,
                              const py::object& seed_value, double sigma_scale, double self_skip,
                              double start = 0.0) {
  if (!std::isfinite(start) || start < 0 || start > kMaxLength) {
    throw py::value_error("start must be a finite number in [0, " + num_str(kMaxLength) +
                          "] (scene units)");
  }
  const int directions = static_cast<int>(int_arg(directions_arg, "directions", 1, 4096));
  distance_arg(distance);
  const std::uint32_t seed = seed_arg(seed_value);
  if (!(sigma_scale >= 0 && sigma_scale <= 3.4e38)) {
    throw py::value_error("sigma_scale must be a finite float32 number >= 0");
  }
  if (!std::isfinite(self_skip) || self_skip < 0 || self_skip > 1e6) {
    throw py::value_error("self_skip must be a finite number in [0, 1e6] (voxels)");
  }
  DensityAOOptions o;
  o.directions = directions;
  o.distance = static_cast<float>(distance);
  o.seed = static_cast<std::uint32_t>(seed);
  o.sigma_scale = static_cast<float>(sigma_scale);
  o.self_skip = static_cast<float>(self_skip);
  o.start = static_cast<float>(start);
  return o;
}

}  // namespace

void bind_medium(py::module_& m) {
  m.def(
      "ao_medium_sphere",
      [](const py::array& positions, const py::array& normals, const Sphere& sphere,
         double tau) {
        const float t = tau_arg(tau);
        return per_point(positions, normals, [&](PointsView p, PointsView n, float* out) {
          ao_medium_sphere(p, n, sphere, t, out);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("sphere"), py::arg("tau"),
      "ao_medium_sphere(positions, normals, sphere, tau) -> float32 (N,)\n\n"
      "Expected cosine-weighted AO of receivers (float32 (N, 3) positions and normals) in or "
      "around a sphere filled with randomly oriented leaves: mean of exp(-sigma * chord) over "
      "the normal's hemisphere, with tau = sigma * R the optical depth from centre to surface "
      "(the DESIGN's tau: AO at the centre = exp(-tau) exactly). One table lookup per point; "
      "receivers outside see the sphere as a soft occluder. A zero normal gives 1. Releases "
      "the GIL.");

  m.def(
      "ao_medium_ellipsoid",
      [](const py::array& positions, const py::array& normals, const Ellipsoid& ellipsoid,
         double tau) {
        const float t = tau_arg(tau);
        return per_point(positions, normals, [&](PointsView p, PointsView n, float* out) {
          ao_medium_ellipsoid(p, n, ellipsoid, t, out);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("ellipsoid"), py::arg("tau"),
      "ao_medium_ellipsoid(positions, normals, ellipsoid, tau) -> float32 (N,)\n\n"
      "ao_medium_sphere after mapping the ellipsoid to the unit sphere (docs/DESIGN.md, "
      "'The method ladder'). "
      "Approximation: exact for spheres; for an elongated ellipsoid it is the medium whose "
      "optical depth centre-to-surface is tau along every axis, with the cosine lobe taken in "
      "the mapped frame.");

  m.def(
      "ao_medium_shells",
      [](const py::array& positions, const py::array& normals,
         const std::vector<Ellipsoid>& shells, const py::object& tau,
         const std::string& combine) {
        const std::vector<float> taus = taus_arg(tau, shells.size());
        const MediumCombine c = combine_arg(combine);
        return per_point(positions, normals, [&](PointsView p, PointsView n, float* out) {
          ao_medium_shells(p, n, shells, taus, c, out);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("shells"), py::arg("tau"),
      py::arg("combine") = "product",
      "ao_medium_shells(positions, normals, shells, tau, combine=\"product\") -> float32 (N,)\n\n"
      "Several media (list of Ellipsoid). tau: one number, or one per shell (a uniform leaf "
      "density sigma gives tau_k = sigma * R_k). combine: \"product\" (every shell, inside as "
      "a medium, outside as a soft occluder; independent transmittances) or \"nearest\" (the "
      "shell with the closest centre only, Hegeman's rule).");

  m.def(
      "medium_ao",
      [](double r, double cos_beta, double tau) {
        if (!std::isfinite(r) || r < 0) throw py::value_error("r must be a finite number >= 0");
        if (!std::isfinite(cos_beta)) throw py::value_error("cos_beta must be finite");
        const float t = tau_arg(tau);
        return MediumTable::get().ao(static_cast<float>(r), static_cast<float>(cos_beta), t);
      },
      py::arg("r"), py::arg("cos_beta"), py::arg("tau"),
      "medium_ao(r, cos_beta, tau) -> float\n\n"
      "The tabulated expectation itself: r = |x - C| / R, cos_beta = n . (x - C) / |x - C| "
      "(+1 = facing away from the centre), tau = sigma * R.");

  m.def(
      "medium_ao_quadrature",
      [](double r, double cos_beta, double tau, const py::object& samples) {
        if (!std::isfinite(r) || r < 0) throw py::value_error("r must be a finite number >= 0");
        if (!std::isfinite(cos_beta)) throw py::value_error("cos_beta must be finite");
        return medium_ao_quadrature(r, cos_beta, tau_arg(tau),
                                    static_cast<int>(int_arg(samples, "samples", 1, 1 << 16)));
      },
      py::arg("r"), py::arg("cos_beta"), py::arg("tau"), py::arg("samples") = 2048,
      "medium_ao_quadrature(r, cos_beta, tau, samples=2048) -> float\n\n"
      "The same expectation by direct numerical integration (no table): the reference the "
      "table is built from and checked against.");

  py::class_<DensityGrid>(m, "DensityGrid",
                          "Leaf area voxelised into an extinction grid (sigma = area / (2 * "
                          "voxel volume)) with a mip pyramid; AO by line integrals through it "
                          "(docs/DESIGN.md, 'The method ladder'). Build once, query many "
                          "times: the query cost does not "
                          "depend on the triangle count.")
      .def(py::init(&make_grid), py::arg("vertices"), py::arg("triangles"),
           py::arg("resolution") = 48,
           "DensityGrid(vertices, triangles, resolution=48)\n\n"
           "vertices: float32 (V, 3); triangles: int32 (M, 3), two-sided leaves (and branches; "
           "closed surfaces count twice their silhouette). resolution: voxels along the "
           "bounding box's longest side, 1..1024. An empty mesh gives an empty grid (AO = 1). "
           "Releases the GIL while building.")
      .def(
          "ao",
          [](const DensityGrid& self, const py::array& points, const py::array& normals,
             const py::object& directions, double distance, const py::object& seed,
             double sigma_scale,
             double self_skip, double start, bool bent_normals) -> py::object {
            const DensityAOOptions o =
                grid_options(directions, distance, seed, sigma_scale, self_skip, start);
            if (!bent_normals) {
              return per_point(points, normals, [&](PointsView p, PointsView n, float* out) {
                self.ao(p, n, o, out);
              }, "points");
            }
            const Receivers r = receivers_arg(points, normals, "points");
            py::array_t<float> ao = new_floats(r.positions.size);
            py::array_t<float> bent({static_cast<py::ssize_t>(r.positions.size),
                                     static_cast<py::ssize_t>(3)});
            float* dst = ao.mutable_data();
            float* bent_dst = bent.mutable_data();
            {
              py::gil_scoped_release release;
              self.ao(r.positions, r.normals, o, dst, bent_dst);
            }
            return py::make_tuple(ao, bent);
          },
          py::arg("points"), py::arg("normals"), py::arg("directions") = 32,
          py::arg("distance") = kInf, py::arg("seed") = 0, py::arg("sigma_scale") = 1.0,
          py::arg("self_skip") = 1.0, py::arg("start") = 0.0, py::arg("bent_normals") = false,
          "ao(points, normals, directions=32, distance=inf, seed=0, sigma_scale=1.0, "
          "self_skip=1.0, start=0.0, bent_normals=False) -> float32 (N,), or (ao, bent) with "
          "bent_normals\n\n"
          "Mean over `directions` cosine-weighted directions of exp(-sigma_scale * integral of "
          "sigma) along each ray, cut at `distance` (Cycles' AO distance). The direction set "
          "is rotated per point from (row index, seed): deterministic, thread-count "
          "independent. self_skip: voxels at the start of each ray read from a coarser level, "
          "so a receiver on a leaf is not shaded by its own leaf (0 = off). start: integrate "
          "only beyond this distance (scene units; see ao_near_far). A zero normal gives 1. "
          "bent_normals=True also returns float32 (N, 3): the transmittance-weighted mean "
          "direction, normalised (the grid's estimate of the ray tracer's bent normal; all "
          "blocked: the unit normal; zero normal: (0, 0, 0)). Releases the GIL.")
      .def(
          "optical_depth",
          [](const DensityGrid& self, const py::object& origin, const py::object& direction,
             double distance, double self_skip) {
            distance_arg(distance);
            if (!std::isfinite(self_skip) || self_skip < 0 || self_skip > 1e6) {
              throw py::value_error("self_skip must be a finite number in [0, 1e6] (voxels)");
            }
            const Vec3 o = point3_arg(origin, "origin"), d = direction_arg(direction, "direction");
            return self.optical_depth(o, d, static_cast<float>(distance),
                                      static_cast<float>(self_skip), 0.0f);
          },
          py::arg("origin"), py::arg("direction"), py::arg("distance") = kInf,
          py::arg("self_skip") = 0.0,
          "optical_depth(origin, direction, distance=inf, self_skip=0.0) -> float\n\n"
          "Integral of sigma along one ray on the finest level (no cone widening). direction: any "
          "non-zero length.")
      .def_property_readonly(
          "shape", [](const DensityGrid& g) { return py::make_tuple(g.nx(), g.ny(), g.nz()); },
          "(nx, ny, nz) voxels of the finest level.")
      .def_property_readonly("voxel_size", &DensityGrid::voxel_size, "Voxel edge, world units.")
      .def_property_readonly(
          "origin",
          [](const DensityGrid& g) {
            const Vec3 o = g.origin();
            return py::make_tuple(o.x, o.y, o.z);
          },
          "World position of the grid's minimum corner.")
      .def_property_readonly("total_area", &DensityGrid::total_area,
                             "Sum of the triangle areas deposited in the grid.")
      .def_property_readonly("levels", &DensityGrid::levels, "Mip levels (1 = finest only).")
      .def(
          "sigma",
          [](const DensityGrid& g, const py::object& level_arg) {
            const int level = static_cast<int>(int_arg(level_arg, "level", 0, g.levels() - 1));
            const std::vector<float>& s = g.sigma_level(level);
            int d[3] = {g.nx(), g.ny(), g.nz()};
            for (int l = 0; l < level; ++l)
              for (int& k : d) k = (k + 1) / 2;
            // stored x fastest: as a C array that is [z][y][x]; hand back (nx, ny, nz)
            py::array_t<float> a({d[2], d[1], d[0]});
            std::copy(s.begin(), s.end(), a.mutable_data());
            return a.attr("transpose")(2, 1, 0).attr("copy")();
          },
          py::arg("level") = 0,
          "sigma(level=0) -> float32 (nx, ny, nz): extinction per world unit of each voxel.")
      .def("__repr__", [](const DensityGrid& g) {
        std::ostringstream s;
        s << "<DensityGrid " << g.nx() << "x" << g.ny() << "x" << g.nz()
          << " voxel " << g.voxel_size() << ", area " << g.total_area() << ">";
        return s.str();
      });

  m.def(
      "ao_near_far",
      [](const RayTracer& tracer, const DensityGrid& grid, const py::array& points,
         const py::array& normals, double near, const py::object& samples,
         const py::object& directions, double distance, const py::object& seed,
         double sigma_scale, const py::object& vertex_ids, const py::object& triangle_ids,
         int point_group) {
        length_arg(near, "near");
        const DensityAOOptions far = grid_options(directions, distance, seed, sigma_scale, 0.0);
        RayTraceOptions rt;
        rt.samples = static_cast<int>(int_arg(samples, "samples", 1, kMaxSamples));
        rt.distance = static_cast<float>(distance);
        rt.seed = far.seed;
        rt.point_group = point_group;
        const Receivers r = receivers_arg(points, normals, "points");
        OwnPrimitives own;
        own.vertex_ids = ids_arg(vertex_ids, "vertex_ids", r.positions.size);
        own.triangle_ids = ids_arg(triangle_ids, "triangle_ids", r.positions.size);
        py::array_t<float> out = new_floats(r.positions.size);
        float* dst = out.mutable_data();
        {
          py::gil_scoped_release release;
          ao_near_far(tracer, grid, r.positions, r.normals, static_cast<float>(near), own, rt,
                      far, dst);
        }
        return out;
      },
      py::arg("tracer"), py::arg("grid"), py::arg("points"), py::arg("normals"),
      py::arg("near"), py::arg("samples") = 64, py::arg("directions") = 32,
      py::arg("distance") = kInf, py::arg("seed") = 0, py::arg("sigma_scale") = 1.0,
      py::arg("vertex_ids") = py::none(), py::arg("triangle_ids") = py::none(),
      py::arg("point_group") = 1,
      "ao_near_far(tracer, grid, points, normals, near, samples=64, directions=32, "
      "distance=inf, seed=0, sigma_scale=1.0, vertex_ids=None, triangle_ids=None, "
      "point_group=1) -> float32 (N,)\n\n"
      "Near exact, far statistical: tracer.ao(points, normals, samples, distance=min(near, "
      "distance), vertex_ids, triangle_ids, point_group) times grid.ao(points, normals, directions, "
      "distance, start=near, self_skip=0). Contact shadows from real geometry (each receiver "
      "named by its own primitives starts as in tracer.ao: a vertex at Cycles' bake point, "
      "its samples cast at every face corner), the canopy's bulk from the density grid; the "
      "product of the two averages assumes near and far occlusion are independent.");
}

}  // namespace canopy_ao::py_bind
