#include "arrays.h"

namespace canopy_ao::py_bind {
void bind_fitting(py::module_& m) {}
}  // namespace canopy_ao::py_bind
