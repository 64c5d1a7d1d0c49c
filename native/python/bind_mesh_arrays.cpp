// Canopy AO — Python bindings for the mesh arrays of a bake (mesh_arrays.h): world-space
// receivers in place, grey RGBA colours out. No copies: numpy buffers are read and written in
// place with the GIL released.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <sstream>
#include <string>

#include "arrays.h"
#include "canopy_ao/mesh_arrays.h"
#include "canopy_ao/mesh_components.h"

namespace canopy_ao::py_bind {

namespace {

// An (N, 3) float32 C-contiguous writeable array (any values: to_world fixes normals itself).
float* rows3_writeable(const py::array& a, const char* name) {
  rows3_arg(a, name, /*allow_empty=*/true);
  if (!a.writeable()) throw py::value_error(std::string(name) + " must be writeable");
  return static_cast<float*>(const_cast<void*>(a.data()));
}

}  // namespace

void bind_mesh_arrays(py::module_& m) {
  m.def(
      "connected_components",
      [](const py::object& n_vertices, const py::array& triangles) {
        const auto n = static_cast<std::size_t>(int_arg(n_vertices, "n_vertices", 0, 0x7fffffff));
        std::size_t count = 0;
        const std::int32_t* t = triangles_arg(triangles, "triangles", n, &count);
        py::array_t<std::int64_t> out(static_cast<py::ssize_t>(n));
        std::int64_t* o = out.mutable_data();
        {
          py::gil_scoped_release release;
          const std::vector<std::int64_t> labels = connected_components(n, t, count);
          std::copy(labels.begin(), labels.end(), o);
        }
        return out;
      },
      py::arg("n_vertices"), py::arg("triangles"),
      "Each vertex's connected component, int64 (n_vertices,) in [0, #components), numbered in "
      "order of each component's first vertex; a vertex no triangle uses is its own. "
      "triangles: int32 (M, 3), C-contiguous, indices in [0, n_vertices) (else ValueError).");
  m.def(
      "to_world",
      [](const py::array& positions, const py::array& normals, const py::object& matrix) {
        float* p = rows3_writeable(positions, "positions");
        float* n = rows3_writeable(normals, "normals");
        if (positions.shape(0) != normals.shape(0)) {
          std::ostringstream s;
          s << "positions and normals must have the same number of rows, got "
            << positions.shape(0) << " and " << normals.shape(0);
          throw py::value_error(s.str());
        }
        double mat[16];
        const bool has_matrix = !matrix.is_none();
        if (has_matrix) {
          const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>(matrix);
          if (a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4)
            throw py::value_error("matrix must be a 4x4 matrix, got shape " + shape_str(a));
          for (int i = 0; i < 16; ++i) {
            mat[i] = a.data()[i];
            if (!std::isfinite(mat[i])) throw py::value_error("matrix has a non-finite value");
          }
        }
        const std::size_t rows = static_cast<std::size_t>(positions.shape(0));
        py::gil_scoped_release release;
        to_world_in_place(p, n, rows, has_matrix ? mat : nullptr);
      },
      py::arg("positions"), py::arg("normals"), py::arg("matrix") = py::none(),
      "to_world(positions, normals, matrix=None) -> None\n\n"
      "Receivers into world space, in place: positions and normals float32 (N, 3), "
      "C-contiguous, writeable. matrix (4x4, row-major, e.g. an object's matrix_world): "
      "positions become M p + t and normals the inverse transpose of M times n (a singular M: "
      "its cofactors, the normal of the face each becomes); None or the identity leaves "
      "positions untouched. Then every normal is unit length: kept if its squared length is "
      "within 1e-6 of 1, (0, 0, 1) if it is zero or not finite, else normalised. One parallel "
      "pass.");

  m.def(
      "gray_rgba",
      [](const py::array& values) {
        require_dtype(values, "values", py::dtype::of<float>(), "float32");
        if (values.ndim() != 1)
          throw py::value_error("values must have shape (N,), got " + shape_str(values));
        const std::size_t n = static_cast<std::size_t>(values.shape(0));
        const float* v = static_cast<const float*>(values.data());
        return compute(n, [&](float* o) { gray_rgba(v, n, o); }, 4);
      },
      py::arg("values"),
      "gray_rgba(values) -> float32 (N, 4)\n\n"
      "(v, v, v, 1) per value of values, float32 (N,) C-contiguous: a grey colour attribute's "
      "data for foreach_set. One parallel pass.");
}

}  // namespace canopy_ao::py_bind
