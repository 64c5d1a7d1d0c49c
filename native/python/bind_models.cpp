// Canopy AO — Python bindings for the analytic AO models (canopy_model.h, occluders.h, grass.h,
// reeves_blau.h). Arrays are checked in arrays.h and never copied; every compute call releases
// the GIL. std::invalid_argument from the core becomes ValueError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <limits>
#include <string>
#include <vector>

#include "arrays.h"
#include "canopy_ao/canopy_model.h"
#include "canopy_ao/grass.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/reeves_blau.h"

namespace canopy_ao::py_bind {

namespace {

struct Receivers {
  PointsView positions, normals;
};

Receivers receivers_arg(const py::array& positions, const py::array& normals) {
  Receivers r{points_arg(positions, "positions", /*allow_empty=*/true),
              points_arg(normals, "normals", /*allow_empty=*/true)};
  check_same_rows(r.positions, "positions", r.normals, "normals");
  return r;
}

OccluderLaw law_arg(const std::string& s) {
  if (s == "solid_opacity") return OccluderLaw::SolidOpacity;
  if (s == "medium") return OccluderLaw::Medium;
  throw py::value_error("law must be \"solid_opacity\" or \"medium\", got \"" + s + "\"");
}

ShellCombine combine_arg(const std::string& s) {
  if (s == "product") return ShellCombine::Product;
  if (s == "nearest") return ShellCombine::Nearest;
  throw py::value_error("combine must be \"product\" or \"nearest\", got \"" + s + "\"");
}

// Runs fn(out) without the GIL on a new (N,) float32 array.
template <class Fn>
py::array_t<float> compute(std::size_t n, Fn&& fn) {
  py::array_t<float> out = new_floats(n);
  float* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    fn(o);
  }
  return out;
}

}  // namespace

void bind_models(py::module_& m) {
  m.def(
      "ao_canopy_sphere",
      [](const py::array& positions, const py::array& normals, const Sphere& sphere, float tau,
         float band) {
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size, [&](float* o) {
          ao_canopy_sphere(r.positions, r.normals, sphere, CanopyOptions{tau, band}, o);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("sphere"), py::arg("tau"),
      py::arg("band") = 0.1,
      "Canopy-shell AO for one sphere (Hegeman 2006 Eq. 4-6, scale-free tau: AO at the centre "
      "= exp(-tau)). positions, normals: float32 (N, 3); returns float32 (N,) in [0, 1], "
      "1 = open sky. Points outside the shell see it as a horizon-clipped sphere occluder of "
      "opacity 1 - exp(-4 tau/3), blended over `band` shell radii so AO is continuous. Zero "
      "normals face away from the centre.");

  m.def(
      "ao_canopy_ellipsoid",
      [](const py::array& positions, const py::array& normals, const Ellipsoid& ellipsoid,
         float tau, float band) {
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size, [&](float* o) {
          ao_canopy_ellipsoid(r.positions, r.normals, ellipsoid, CanopyOptions{tau, band}, o);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("ellipsoid"), py::arg("tau"),
      py::arg("band") = 0.1,
      "Canopy-shell AO for one ellipsoid: mapped to the unit sphere (docs/DESIGN.md, "
      "'The method ladder'), then as "
      "ao_canopy_sphere. Returns float32 (N,) in [0, 1].");

  m.def(
      "ao_canopy_shells",
      [](const py::array& positions, const py::array& normals,
         const std::vector<Ellipsoid>& shells, float tau, const std::string& combine,
         float band) {
        const Receivers r = receivers_arg(positions, normals);
        const ShellCombine c = combine_arg(combine);
        return compute(r.positions.size, [&](float* o) {
          ao_canopy_shells(r.positions, r.normals, shells, CanopyOptions{tau, band}, c, o);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("shells"), py::arg("tau"),
      py::arg("combine") = "product", py::arg("band") = 0.1,
      "AO from several shells (list of Ellipsoid). combine=\"product\": product of every "
      "shell's visibility (in-shell law inside, occluder law outside) - no seams; "
      "\"nearest\": the paper's closest-centre shell alone. Returns float32 (N,) in [0, 1].");

  m.def(
      "ao_reeves_blau",
      [](const py::array& positions, const py::array& normals, const Ellipsoid& ellipsoid,
         float tau) {
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size,
                       [&](float* o) { ao_reeves_blau(r.positions, ellipsoid, tau, o); });
      },
      py::arg("positions"), py::arg("normals"), py::arg("ellipsoid"), py::arg("tau"),
      "Reeves-Blau baseline: exp(-tau * depth / R), depth = max(R - |x - C|, 0) in the "
      "ellipsoid's unit frame (normals unused). Returns float32 (N,) in [0, 1].");

  m.def(
      "ao_occluders",
      [](const py::array& positions, const py::array& normals,
         const std::vector<Ellipsoid>& shells, float tau, float epsilon, bool solid,
         const std::string& law, float distance) {
        const OccluderOptions opt{tau, epsilon, solid, law_arg(law), distance};
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size, [&](float* o) {
          ao_occluders(r.positions, r.normals, shells, opt, o);
        });
      },
      py::arg("positions"), py::arg("normals"), py::arg("shells"), py::arg("tau"),
      py::arg("epsilon") = 1e-3, py::arg("solid") = false, py::arg("law") = "medium",
      py::arg("distance") = std::numeric_limits<float>::infinity(),
      "Shells seen from outside as horizon-clipped, cosine-weighted occluders, combined as "
      "prod(1 - occ_i). law=\"solid_opacity\": a solid sphere (the shell's projected-area "
      "radius) scaled by the opacity 1 - exp(-4 tau/3); law=\"medium\": that sphere filled "
      "with a uniform random medium of tau per radius, occ = 1 - medium table AO (exact "
      "expectation, short chords near the rim); solid=True: opaque spheres (law ignored). Each "
      "occluder is ignored beyond d_far = r / sin(acos(1 - epsilon/2pi)) (epsilon=0: no "
      "cut-off), found through a uniform grid. distance: the AO distance, a hard cut-off as "
      "Cycles' (only what lies within it along a ray counts; inf = unlimited). Receivers "
      "inside a shell skip it. Returns float32 (N,) in [0, 1].");

  py::class_<OccluderField>(m, "OccluderField",
                            "Occluders with their spatial grid, built once for repeated "
                            "ao() calls (same law as ao_occluders).")
      .def(py::init([](const std::vector<Ellipsoid>& shells, float tau, float epsilon,
                       bool solid, const std::string& law, float distance) {
             return new OccluderField(
                 shells, OccluderOptions{tau, epsilon, solid, law_arg(law), distance});
           }),
           py::arg("shells"), py::arg("tau"), py::arg("epsilon") = 1e-3,
           py::arg("solid") = false, py::arg("law") = "medium",
           py::arg("distance") = std::numeric_limits<float>::infinity())
      .def(
          "ao",
          [](const OccluderField& f, const py::array& positions, const py::array& normals) {
            const Receivers r = receivers_arg(positions, normals);
            return compute(r.positions.size,
                           [&](float* o) { f.ao(r.positions, r.normals, o); });
          },
          py::arg("positions"), py::arg("normals"), "AO at (N, 3) points; float32 (N,).")
      .def_property_readonly("max_candidates", &OccluderField::max_candidates,
                             "Largest number of occluders one receiver can test.")
      .def("__len__", &OccluderField::size);

  m.def("sphere_occlusion", &sphere_occlusion, py::arg("cos_theta"), py::arg("sin2_sigma"),
        "Exact fraction of cosine-weighted AO blocked by a solid sphere whose centre is at "
        "angle theta from the normal and whose angular radius is sigma (sin^2 sigma = "
        "(r/d)^2), clipped at the horizon (Snyder's sphere form factor). In [0, 1]; "
        "sin2_sigma >= 1 (receiver on the sphere) gives (1 + cos theta)/2.");
  m.def("shell_opacity", &shell_opacity, py::arg("tau"),
        "Opacity of a leaf shell seen from outside: 1 - exp(-4 tau / 3) (mean chord 4R/3).");

  m.def(
      "ao_grass",
      [](const py::array& positions, const py::array& normals, float ground_height,
         float blade_height, const py::object& up, float floor) {
        const Receivers r = receivers_arg(positions, normals);
        GrassOptions o;
        o.ground_height = ground_height;
        o.blade_height = blade_height;
        o.up = vec3_arg(up, "up");
        o.floor = floor;
        return compute(r.positions.size,
                       [&](float* out) { ao_grass(r.positions, r.normals, o, out); });
      },
      py::arg("positions"), py::arg("normals"), py::arg("ground_height"),
      py::arg("blade_height"), py::arg("up") = py::make_tuple(0.0f, 0.0f, 1.0f),
      py::arg("floor") = 0.05,
      "Grass AO (Hegeman 2006 Eq. 9): (Pz / 2h)(1 + cos theta), Pz = height above "
      "ground_height along `up` clamped to [0, h], theta the angle between normal and up; "
      "clamped to [floor, 1] (ground points under grass get `floor`). Zero normals count as "
      "horizontal. Returns float32 (N,).");
}

}  // namespace canopy_ao::py_bind
