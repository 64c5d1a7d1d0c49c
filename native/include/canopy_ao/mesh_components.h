// Canopy AO — the connected pieces of a mesh (the role guess's first fact, core/roles.py:
// Sapling's branches are hundreds of separate tubes, a leaf card is one piece per leaf).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace canopy_ao {

/// Each vertex's connected component: labels[v] in [0, #components), numbered in the order of
/// each component's first (lowest) vertex; a vertex no triangle uses is a component of its own.
/// triangles: #F by 3 vertex indices, each in [0, n_vertices) (PRE; the bindings check).
/// Union-find with the smaller root kept (so a root is its component's lowest vertex) and path
/// halving: near-linear in V + F, whatever the mesh's diameter. The same labels as
/// core/roles.py's bulk numpy version, which it replaces on the bake's path.
std::vector<std::int64_t> connected_components(std::size_t n_vertices,
                                               const std::int32_t* triangles,
                                               std::size_t triangle_count);

}  // namespace canopy_ao
