// Canopy AO — the arrays a bake exchanges with a mesh: receivers brought into world space on
// the way in, AO spread into RGBA colours on the way out (docs/DESIGN.md, 'Data flow').
//
// Both are one parallel pass over the vertices, in place or into a preallocated buffer: the
// add-on's own share of a bake stays small beside Blender's I/O (docs/DESIGN.md, 'Facts
// measured in Blender').
#pragma once

#include <cstddef>

namespace canopy_ao {

/// Unit-length rule of to_world_in_place: a normal whose squared length is within this of 1 is
/// left as it is (Blender's own normals, bit for bit); any other is divided by its length.
constexpr double kUnitNormalSlack = 1e-6;

/// Receivers in world space, in place: positions (n rows of 3 floats) become M·p + t, normals
/// the inverse transpose of M times n (non-uniform scale; M = the upper-left 3×3 of `matrix`,
/// row-major 4×4; a singular M, a scale of 0 on an axis, has its cofactors instead: the normal
/// of the face each becomes, cof(M)(a × b) = Ma × Mb), computed in double.
/// matrix == nullptr (or the identity) leaves positions untouched. Then every normal is made
/// unit length: within kUnitNormalSlack of unit it is kept, a zero or non-finite one becomes
/// (0, 0, 1), any other is normalised. Rows are independent (parallel_for_blocks).
void to_world_in_place(float* positions, float* normals, std::size_t n, const double* matrix);

/// (v, v, v, 1) per value, into rgba (4·n floats): a grey colour attribute's data.
void gray_rgba(const float* values, std::size_t n, float* rgba);

}  // namespace canopy_ao
