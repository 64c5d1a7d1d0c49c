// Canopy AO — the pybind11 module `canopy_ao._core`. Each area binds itself in its own file;
// this file only creates the module, the error type, and the thread controls.
#include <pybind11/pybind11.h>

#include <cstring>
#include <stdexcept>

#include "arrays.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/stage_clock.h"

namespace py = pybind11;

namespace canopy_ao::py_bind {
void bind_fitting(py::module_& m);
void bind_models(py::module_& m);
void bind_raytrace(py::module_& m);
void bind_texel(py::module_& m);
void bind_medium(py::module_& m);
void bind_features(py::module_& m);
void bind_mesh_arrays(py::module_& m);
void bind_scene_plan(py::module_& m);
}  // namespace canopy_ao::py_bind

// Most worker threads set_max_threads takes.
constexpr long long kMaxThreadCap = 1 << 16;

PYBIND11_MODULE(_core, m) {
  using namespace canopy_ao;
  m.doc() =
      "Canopy AO native core: proxy fitting (spheres, ellipsoids, shells), approximate AO "
      "models and an Embree ray-traced reference. Arrays: float32 (N, 3) positions/normals, "
      "int32 (M, 3) triangles; results float32 (N,) in [0, 1], 1 = open sky.";
  m.attr("__version__") = CANOPY_AO_VERSION;
  // The accepted input range (arrays.h), for the add-on's own checks: a value outside it is
  // refused with the option's or the object's name before any call (core/settings.py,
  // blender/mesh_io.py), and tests hold those to these numbers.
  py::dict limits;
  limits["coordinate"] = py_bind::kMaxCoordinate;
  limits["min_length"] = py_bind::kMinLength;
  limits["max_length"] = py_bind::kMaxLength;
  limits["tau"] = py_bind::kMaxTau;
  limits["samples"] = py_bind::kMaxSamples;
  limits["threads"] = kMaxThreadCap;
  m.attr("LIMITS") = limits;

  // register_exception: translation and the Python type in one call, the same in pybind11 2.10
  // and 3.x (a static py::exception called as error(msg) is deprecated in 3.x). The translator
  // below is registered later, so it runs first and decodes messages safely.
  py::register_exception<Error>(m, "CanopyAOError", PyExc_RuntimeError);
  static PyObject* const error_type = [&m] {
    PyObject* t = m.attr("CanopyAOError").ptr();
    Py_INCREF(t);  // lives as long as the process, as the module's own type does
    return t;
  }();
  // Messages may quote a path, which need not be UTF-8 (paths pass byte for byte): decode
  // with backslashreplace, so the message is never lost (pybind's strict decode left an empty
  // ValueError).
  py::register_exception_translator([](std::exception_ptr p) {
    auto raise = [](PyObject* type, const char* what) {
      PyObject* msg = PyUnicode_DecodeUTF8(what, static_cast<Py_ssize_t>(std::strlen(what)),
                                           "backslashreplace");
      PyErr_SetObject(type, msg);
      Py_XDECREF(msg);
    };
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Error& e) {
      raise(error_type, e.what());
    } catch (const std::invalid_argument& e) {
      raise(PyExc_ValueError, e.what());
    } catch (const std::domain_error& e) {
      raise(PyExc_ValueError, e.what());
    } catch (const std::length_error& e) {
      raise(PyExc_ValueError, e.what());
    }
  });

  m.def(
      "set_max_threads",
      [](const py::object& n) {
        return set_max_threads(static_cast<int>(py_bind::int_arg(n, "n", 0, kMaxThreadCap)));
      },
      py::arg("n"),
      "Caps worker threads for later calls (0 = all cores; n in [0, 65536], else ValueError). "
      "Returns the previous cap. "
        "Results do not depend on the thread count.");
  m.def("max_threads", &max_threads, "Worker threads calls use now.");
  m.def("set_stage_profiling", &set_stage_profiling, py::arg("on"),
        "Turns native stage timing on or off (process-wide; results never depend on it). "
        "Returns the previous state.");
  m.def(
      "take_stage_seconds",
      [] {
        py::dict out;  // insertion order: the order stages were first seen
        for (const auto& [name, total] : take_stage_seconds()) {
          out[py::str(name)] = py::make_tuple(total.first, total.second);
        }
        return out;
      },
      "Seconds per native stage since the last call, {name: (seconds, sections)}, in the "
      "order first seen, then cleared. Stages on worker threads sum every thread's seconds "
      "(their names say CPU). Empty while profiling is off.");

  py_bind::bind_fitting(m);
  py_bind::bind_models(m);
  py_bind::bind_raytrace(m);
  py_bind::bind_texel(m);
  py_bind::bind_medium(m);
  py_bind::bind_features(m);
  py_bind::bind_mesh_arrays(m);
  py_bind::bind_scene_plan(m);
}
