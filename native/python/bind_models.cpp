// Canopy AO — Python bindings for the analytic AO models (canopy_model.h, occluders.h, grass.h,
// reeves_blau.h). Arrays are checked in arrays.h and never copied; every compute call releases
// the GIL. std::invalid_argument from the core becomes ValueError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "arrays.h"
#include "canopy_ao/canopy_model.h"
#include "canopy_ao/grass.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/patches.h"
#include "canopy_ao/reeves_blau.h"

namespace canopy_ao::py_bind {

namespace {

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

/// An (N, 3) float64 C-contiguous array of finite values within +-limit (patches and their
/// receivers are taken in double: walls.py's numbers, and a few patches cost nothing to pass).
const double* doubles3_arg(const py::array& a, const char* name, double limit, std::size_t* n) {
  require_dtype(a, name, py::dtype::of<double>(), "float64");
  if (a.ndim() != 2 || a.shape(1) != 3) {
    throw py::value_error(std::string(name) + " must have shape (N, 3), got " + shape_str(a));
  }
  *n = static_cast<std::size_t>(a.shape(0));
  const auto* d = static_cast<const double*>(a.data());
  for (std::size_t i = 0; i < 3 * *n; ++i) {
    if (!(std::fabs(d[i]) <= limit)) {
      throw py::value_error(std::string(name) + " must hold finite values within +-" +
                            num_str(limit) + ", got " + num_str(d[i]) + " in row " +
                            std::to_string(i / 3));
    }
  }
  return d;
}

/// The patches from corners (M, 3), counts int32 (P,) (each >= 3, summing to M) and planes
/// float64 (P, 5): unit normal, offset, diameter.
std::vector<PatchPolygon> patches_arg(const py::array& corners, const py::array& counts,
                                      const py::array& planes) {
  std::size_t m = 0;
  const double* c = doubles3_arg(corners, "corners", kMaxCoordinate, &m);
  require_dtype(counts, "counts", py::dtype::of<std::int32_t>(), "int32");
  require_dtype(planes, "planes", py::dtype::of<double>(), "float64");
  if (counts.ndim() != 1) {
    throw py::value_error("counts must have shape (P,), got " + shape_str(counts));
  }
  const auto np = static_cast<std::size_t>(counts.shape(0));
  if (planes.ndim() != 2 || planes.shape(1) != 5 ||
      static_cast<std::size_t>(planes.shape(0)) != np) {
    throw py::value_error("planes must have shape (" + std::to_string(np) +
                          ", 5) (normal, offset, diameter per patch), got " + shape_str(planes));
  }
  const auto* k = static_cast<const std::int32_t*>(counts.data());
  const auto* pl = static_cast<const double*>(planes.data());
  std::vector<PatchPolygon> out(np);
  std::size_t first = 0;
  for (std::size_t j = 0; j < np; ++j) {
    if (k[j] < 3 || static_cast<std::size_t>(k[j]) > m - first) {
      throw py::value_error("counts must be >= 3 each and sum to the corners' " +
                            std::to_string(m) + " rows, got " + std::to_string(k[j]) +
                            " for patch " + std::to_string(j));
    }
    PatchPolygon& p = out[j];
    p.corners.assign(c + 3 * first, c + 3 * (first + k[j]));
    first += static_cast<std::size_t>(k[j]);
    const double* q = pl + 5 * j;
    const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    if (!(std::fabs(len - 1.0) <= 1e-6)) {
      throw py::value_error("planes' normals must have unit length, got length " + num_str(len) +
                            " for patch " + std::to_string(j));
    }
    if (!(std::fabs(q[3]) <= 2 * kMaxCoordinate)) {
      throw py::value_error("planes' offsets must be finite within +-" +
                            num_str(2 * kMaxCoordinate) + ", got " + num_str(q[3]));
    }
    if (!(q[4] >= kMinLength && q[4] <= kMaxLength)) {
      throw py::value_error("planes' diameters must be lengths in [" + num_str(kMinLength) +
                            ", " + num_str(kMaxLength) + "], got " + num_str(q[4]));
    }
    std::copy(q, q + 3, p.normal);
    p.offset = q[3];
    p.diameter = q[4];
  }
  if (first != m) {
    throw py::value_error("counts must sum to the corners' " + std::to_string(m) +
                          " rows, got " + std::to_string(first));
  }
  return out;
}

}  // namespace

void bind_models(py::module_& m) {
  m.def(
      "ao_canopy_sphere",
      [](const py::array& positions, const py::array& normals, const Sphere& sphere, double tau,
         float band) {
        const CanopyOptions opt{tau_arg(tau), band};
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size, [&](float* o) {
          ao_canopy_sphere(r.positions, r.normals, sphere, opt, o);
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
         double tau, float band) {
        const CanopyOptions opt{tau_arg(tau), band};
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size, [&](float* o) {
          ao_canopy_ellipsoid(r.positions, r.normals, ellipsoid, opt, o);
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
         const std::vector<Ellipsoid>& shells, double tau, const std::string& combine,
         float band) {
        const CanopyOptions opt{tau_arg(tau), band};
        const Receivers r = receivers_arg(positions, normals);
        const ShellCombine c = combine_arg(combine);
        return compute(r.positions.size, [&](float* o) {
          ao_canopy_shells(r.positions, r.normals, shells, opt, c, o);
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
         double tau) {
        const float t = tau_arg(tau);
        const Receivers r = receivers_arg(positions, normals);
        return compute(r.positions.size,
                       [&](float* o) { ao_reeves_blau(r.positions, ellipsoid, t, o); });
      },
      py::arg("positions"), py::arg("normals"), py::arg("ellipsoid"), py::arg("tau"),
      "Reeves-Blau baseline: exp(-tau * depth / R), depth = max(R - |x - C|, 0) in the "
      "ellipsoid's unit frame (normals unused). Returns float32 (N,) in [0, 1].");

  m.def(
      "ao_occluders",
      [](const py::array& positions, const py::array& normals,
         const std::vector<Ellipsoid>& shells, double tau, float epsilon, bool solid,
         const std::string& law, double distance) {
        const OccluderOptions opt{tau_arg(tau), epsilon, solid, law_arg(law),
                                  distance_arg(distance)};
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
      .def(py::init([](const std::vector<Ellipsoid>& shells, double tau, float epsilon,
                       bool solid, const std::string& law, double distance) {
             return new OccluderField(shells, OccluderOptions{tau_arg(tau), epsilon, solid,
                                                              law_arg(law),
                                                              distance_arg(distance)});
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

  m.def(
      "sphere_occlusion",
      [](double cos_theta, double sin2_sigma) {
        if (!std::isfinite(cos_theta)) throw py::value_error("cos_theta must be finite");
        if (!(sin2_sigma >= 0) || !std::isfinite(sin2_sigma)) {
          throw py::value_error("sin2_sigma must be a finite number >= 0, got " +
                                num_str(sin2_sigma));
        }
        return sphere_occlusion(static_cast<float>(std::clamp(cos_theta, -1.0, 1.0)),
                                static_cast<float>(sin2_sigma));
      },
      py::arg("cos_theta"), py::arg("sin2_sigma"),
        "Exact fraction of cosine-weighted AO blocked by a solid sphere whose centre is at "
        "angle theta from the normal and whose angular radius is sigma (sin^2 sigma = "
        "(r/d)^2), clipped at the horizon (Snyder's sphere form factor). In [0, 1]; "
        "sin2_sigma >= 1 (receiver on the sphere) gives (1 + cos theta)/2. cos_theta finite "
        "(clamped to [-1, 1]), sin2_sigma finite >= 0, else ValueError.");
  m.def(
      "canopy_kernel",
      []() { return canopy_kernel() == CanopyKernel::Avx2 ? "avx2" : "portable"; },
      "Kernel the canopy-shell models use: \"avx2\" (AVX2/FMA, where the CPU has them) or "
      "\"portable\" (the build's baseline; forced by CANOPY_AO_KERNEL=portable).");
  m.def(
      "set_canopy_kernel",
      [](const std::string& name) {
        if (name == "portable") return set_canopy_kernel(CanopyKernel::Portable);
        if (name == "avx2") return set_canopy_kernel(CanopyKernel::Avx2);
        throw py::value_error("kernel must be \"portable\" or \"avx2\", got \"" + name + "\"");
      },
      py::arg("name"),
      "Use this canopy-shell kernel from now on (process-wide). ValueError if this CPU cannot "
      "run it.");
  m.def(
      "shell_opacity",
      [](double tau) { return shell_opacity(tau_arg(tau)); },
      py::arg("tau"),
      "Opacity of a leaf shell seen from outside: 1 - exp(-4 tau / 3) (mean chord 4R/3), in "
      "[0, 1]; tau in [0, 1e4].");

  m.def(
      "patch_visibility",
      [](const py::array& corners, const py::array& counts, const py::array& planes,
         const py::array& positions, const py::array& normals, double distance, double near) {
        const std::vector<PatchPolygon> patches = patches_arg(corners, counts, planes);
        std::size_t n = 0, nn = 0;
        const double* p = doubles3_arg(positions, "positions", kMaxCoordinate, &n);
        const double* q = doubles3_arg(normals, "normals", kMaxCoordinate, &nn);
        if (n != nn) {
          throw py::value_error("positions and normals must have the same number of rows, got " +
                                std::to_string(n) + " and " + std::to_string(nn));
        }
        if (!(distance >= kMinLength)) {
          throw py::value_error("distance must be >= " + num_str(kMinLength) +
                                " (inf = unlimited), got " + num_str(distance));
        }
        if (!(near >= 0 && near <= kMaxLength)) {
          throw py::value_error("near must be a finite length >= 0, got " + num_str(near));
        }
        return compute(n, [&](float* o) { patch_visibility(patches, p, q, n, distance, near, o); });
      },
      py::arg("corners"), py::arg("counts"), py::arg("planes"), py::arg("positions"),
      py::arg("normals"), py::arg("distance") = std::numeric_limits<double>::infinity(),
      py::arg("near") = 0.0,
      "Opaque convex patches as occluders (core/walls.py's visibility): float32 (N,) = 1 - sum "
      "over patches of the cosine-weighted form factor each covers of the receiver's "
      "hemisphere between `near` and `distance` (inf = unlimited), clipped to [0, 1]. "
      "corners: float64 (M, 3), each patch's in order about its normal; counts: int32 (P,), "
      "corners per patch (>= 3, summing to M); planes: float64 (P, 5), unit normal, offset "
      "(normal . corners' mean), diameter. positions, normals: float64 (N, 3), unit normals (the "
      "form factor is linear in them; zero: no occlusion). Else ValueError.");

  m.def(
      "ao_grass",
      [](const py::array& positions, const py::array& normals, double ground_height,
         double blade_height, const py::object& up, float floor, const py::object& layer) {
        const Receivers r = receivers_arg(positions, normals);
        GrassOptions o;
        o.ground_height = coordinate_arg(ground_height, "ground_height");
        o.blade_height = length_arg(blade_height, "blade_height");
        o.up = direction_arg(up, "up");
        o.floor = floor;
        blade_layer_arg(layer, &o);
        return compute(r.positions.size,
                       [&](float* out) { ao_grass(r.positions, r.normals, o, out); });
      },
      py::arg("positions"), py::arg("normals"), py::arg("ground_height"),
      py::arg("blade_height"), py::arg("up") = py::make_tuple(0.0f, 0.0f, 1.0f),
      py::arg("floor") = 0.05, py::arg("layer") = py::none(),
      "Grass AO (Hegeman 2006 Eq. 9): (Pz / 2h)(1 + cos theta), Pz = height above "
      "ground_height along `up` clamped to [0, h], theta the angle between normal and up; "
      "clamped to [floor, 1] (ground points under grass get `floor`). Zero normals count as "
      "horizontal. layer: the field's blade layer, float32 (rows, cols), V at s = Pz / h = "
      "i / (rows - 1) and cos theta = -1 + 2 j / (cols - 1), read bilinearly instead of Eq. 9 "
      "(core/grass_layer.py measures it). Returns float32 (N,).");
}

}  // namespace canopy_ao::py_bind
