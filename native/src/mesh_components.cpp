#include "canopy_ao/mesh_components.h"

namespace canopy_ao {

namespace {
/// The root of v, halving the path on the way (every other node points to its grandparent).
inline std::uint32_t find_root(std::vector<std::uint32_t>& parent, std::uint32_t v) {
  while (parent[v] != v) {
    parent[v] = parent[parent[v]];
    v = parent[v];
  }
  return v;
}

inline void unite(std::vector<std::uint32_t>& parent, std::uint32_t a, std::uint32_t b) {
  a = find_root(parent, a);
  b = find_root(parent, b);
  // INV: parent[i] <= i, so each root is its component's lowest vertex.
  if (a < b) {
    parent[b] = a;
  } else if (b < a) {
    parent[a] = b;
  }
}
}  // namespace

std::vector<std::int64_t> connected_components(std::size_t n_vertices,
                                               const std::int32_t* triangles,
                                               std::size_t triangle_count) {
  std::vector<std::uint32_t> parent(n_vertices);
  for (std::size_t v = 0; v < n_vertices; ++v) parent[v] = static_cast<std::uint32_t>(v);
  for (std::size_t f = 0; f < triangle_count; ++f) {
    const auto* t = triangles + 3 * f;
    unite(parent, static_cast<std::uint32_t>(t[0]), static_cast<std::uint32_t>(t[1]));
    unite(parent, static_cast<std::uint32_t>(t[1]), static_cast<std::uint32_t>(t[2]));
  }
  // Roots are lowest vertices, so a single pass in vertex order meets each root before any
  // other vertex of its component: labels come out in order of first vertex.
  std::vector<std::int64_t> labels(n_vertices);
  std::int64_t next = 0;
  for (std::size_t v = 0; v < n_vertices; ++v) {
    const std::uint32_t r = find_root(parent, static_cast<std::uint32_t>(v));
    labels[v] = r == v ? next++ : labels[r];
  }
  return labels;
}

}  // namespace canopy_ao
