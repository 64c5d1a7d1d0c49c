#include "arrays.h"

namespace canopy_ao::py_bind {
void bind_texel(py::module_& m) {}
}  // namespace canopy_ao::py_bind
