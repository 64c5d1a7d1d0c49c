// Canopy AO — Python bindings for the per-vertex occlusion features and their linear model
// (occlusion_features.h): the ray-free "regression" rung. Arrays are checked with the GIL held
// (arrays.h), the work runs with it released.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <string>
#include <vector>

#include "arrays.h"
#include "canopy_ao/density_grid.h"
#include "canopy_ao/occlusion_features.h"

namespace canopy_ao::py_bind {

namespace {

// (N, F) float32 C-contiguous features; returns the row count.
std::size_t features_arg(const py::array& a, int f) {
  require_dtype(a, "features", py::dtype::of<float>(), "float32");
  if (a.ndim() != 2 || a.shape(1) != f) {
    throw py::value_error("features must have shape (N, " + std::to_string(f) + "), got " +
                          shape_str(a));
  }
  return static_cast<std::size_t>(a.shape(0));
}

int feature_count(const py::array& a) {
  if (a.ndim() != 2) throw py::value_error("features must have shape (N, F), got " + shape_str(a));
  return static_cast<int>(a.shape(1));
}

}  // namespace

void bind_features(py::module_& m) {
  py::class_<OcclusionFeatures>(
      m, "OcclusionFeatures",
      "Cheap per-vertex occlusion features from a density grid (optical depth toward the sky in "
      "fixed directions, precomputed per voxel; local leaf density; the normal against up, the "
      "tree's radial direction and its centre; height and radius in the tree). Build once per "
      "scene; compute() costs the same whatever the leaf count.")
      .def(py::init([](const DensityGrid& occluders, int directions) {
             OcclusionFeatureOptions o;
             o.directions = directions;
             if (directions < 6 || directions > 256) {
               throw py::value_error("directions must be in [6, 256], got " +
                                     std::to_string(directions));
             }
             py::gil_scoped_release release;
             return std::make_unique<OcclusionFeatures>(occluders, o);
           }),
           py::arg("occluders"), py::arg("directions") = 24,
           "OcclusionFeatures(occluders, directions=24)\n\n"
           "occluders: DensityGrid of everything that occludes (leaves, branches, grass). "
           "directions: 6..256 fixed directions over the sphere whose optical depth is swept "
           "through the grid once.")
      .def(
          "compute",
          [](const OcclusionFeatures& self, const py::array& positions, const py::array& normals,
             const py::object& center, double radius, double z_min, double z_max) {
            const Receivers r = receivers_arg(positions, normals);
            const PointsView p = r.positions, n = r.normals;
            TreeFrame fr;
            fr.center = point3_arg(center, "center");
            fr.radius = length_arg(radius, "radius");
            fr.z_min = coordinate_arg(z_min, "z_min");
            fr.z_max = coordinate_arg(z_max, "z_max");
            if (fr.z_max < fr.z_min) throw py::value_error("z_min must be <= z_max");
            py::array_t<float> out({static_cast<py::ssize_t>(p.size),
                                    static_cast<py::ssize_t>(OcclusionFeatures::kCount)});
            float* dst = out.mutable_data();
            py::gil_scoped_release release;
            self.compute(p, n, fr, dst);
            return out;
          },
          py::arg("positions"), py::arg("normals"), py::arg("center"), py::arg("radius"),
          py::arg("z_min"), py::arg("z_max"),
          "compute(positions, normals, center, radius, z_min, z_max) -> float32 (N, F)\n\n"
          "Features of each receiver (names: feature_names). center, radius, z_min, z_max: the "
          "tree's vertical axis, horizontal radius and height range (scale-free shape "
          "features). Releases the GIL.")
      .def_property_readonly("directions", &OcclusionFeatures::directions)
      .def_property_readonly_static("feature_names", [](const py::object&) {
        std::vector<std::string> names;
        for (int f = 0; f < OcclusionFeatures::kCount; ++f)
          names.emplace_back(OcclusionFeatures::feature_name(f));
        return names;
      });

  m.def(
      "expand_features",
      [](const py::array& features, const py::array& mean, const py::array& scale) {
        const int f = feature_count(features);
        const std::size_t n = features_arg(features, f);
        const float* mu = floats_arg(mean, "mean", f);
        const float* sc = floats_arg(scale, "scale", f);
        const int P = expanded_size(f);
        py::array_t<float> out({static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(P)});
        const float* x = static_cast<const float*>(features.data());
        float* dst = out.mutable_data();
        {
          py::gil_scoped_release release;
          expand_features(x, n, f, mu, sc, dst);
        }
        return out;
      },
      py::arg("features"), py::arg("mean"), py::arg("scale"),
      "expand_features(features, mean, scale) -> float32 (N, P)\n\n"
      "The regression's terms: z = (features - mean) / scale, then [1, z, z**2, z[:, 1] * z[:, "
      "j != 1]] (squares and the products with the grid AO; P = 3F, plus the 15 products of the "
      "shape features 6-11 when F = 13). mean, scale: float32 (F,), scale "
      "> 0.");
  m.def(
      "predict_features",
      [](const py::array& features, const py::array& mean, const py::array& scale,
         const py::array& weights, const py::object& lo, const py::object& hi,
         int native_features) {
        const int f = feature_count(features);
        const std::size_t n = features_arg(features, f);
        const int fn = native_features < 0 ? f : native_features;
        if (fn < 1 || fn > f) {
          throw py::value_error("native_features must be in [1, " + std::to_string(f) +
                                "], got " + std::to_string(native_features));
        }
        const float* mu = floats_arg(mean, "mean", f);
        const float* sc = floats_arg(scale, "scale", f);
        const float* w = floats_arg(weights, "weights", model_size(f, fn));
        if (lo.is_none() != hi.is_none()) throw py::value_error("give both lo and hi, or neither");
        py::array lo_a, hi_a;
        const float *l = nullptr, *h = nullptr;
        if (!lo.is_none()) {
          lo_a = py::array::ensure(lo), hi_a = py::array::ensure(hi);
          l = floats_arg(lo_a, "lo", f);
          h = floats_arg(hi_a, "hi", f);
        }
        py::array_t<float> out = new_floats(n);
        const float* x = static_cast<const float*>(features.data());
        float* dst = out.mutable_data();
        {
          py::gil_scoped_release release;
          predict_model(x, n, f, fn, mu, sc, w, l, h, dst);
        }
        return out;
      },
      py::arg("features"), py::arg("mean"), py::arg("scale"), py::arg("weights"),
      py::arg("lo") = py::none(), py::arg("hi") = py::none(), py::arg("native_features") = -1,
      "predict_features(features, mean, scale, weights, lo=None, hi=None, native_features=-1)"
      " -> float32 (N,)\n\n"
      "AO = clip(phi @ weights, 0, 1): the fitted regression evaluated. phi: the first "
      "native_features columns (-1: all) expanded as expand_features does, then the rest "
      "(the leaf-piece columns) as [z_e, z_e**2, z[:, 1] * z_e]. lo, hi: float32 (F,) bounds "
      "each feature is clipped to first (a live frame's), or None.");
}

}  // namespace canopy_ao::py_bind
