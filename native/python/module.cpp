// Canopy AO — the pybind11 module `canopy_ao._core`. Each area binds itself in its own file;
// this file only creates the module, the error type, and the thread controls.
#include <pybind11/pybind11.h>

#include "arrays.h"
#include "canopy_ao/parallel.h"

namespace py = pybind11;

namespace canopy_ao::py_bind {
void bind_fitting(py::module_& m);
void bind_models(py::module_& m);
void bind_raytrace(py::module_& m);
void bind_texel(py::module_& m);
void bind_medium(py::module_& m);
void bind_features(py::module_& m);
}  // namespace canopy_ao::py_bind

PYBIND11_MODULE(_core, m) {
  using namespace canopy_ao;
  m.doc() =
      "Canopy AO native core: proxy fitting (spheres, ellipsoids, shells), approximate AO "
      "models and an Embree ray-traced reference. Arrays: float32 (N, 3) positions/normals, "
      "int32 (M, 3) triangles; results float32 (N,) in [0, 1], 1 = open sky.";
  m.attr("__version__") = CANOPY_AO_VERSION;

  static py::exception<Error> error(m, "CanopyAOError", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Error& e) {
      error(e.what());
    }
  });

  m.def("set_max_threads", &set_max_threads, py::arg("n"),
        "Caps worker threads for later calls (0 = all cores). Returns the previous cap. "
        "Results do not depend on the thread count.");
  m.def("max_threads", &max_threads, "Worker threads calls use now.");

  py_bind::bind_fitting(m);
  py_bind::bind_models(m);
  py_bind::bind_raytrace(m);
  py_bind::bind_texel(m);
  py_bind::bind_medium(m);
  py_bind::bind_features(m);
}
