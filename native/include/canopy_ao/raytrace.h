// Canopy AO — ray-traced ambient occlusion with Embree (3 or 4): the exact answer (up to sampling
// noise), the reference every approximate model is checked against, and the source of
// calibration samples (docs/DESIGN.md, 'The method ladder' and 'Auto mode').
//
// What it computes (docs/DESIGN.md, 'What AO means here': Cycles' meaning):
//
//     AO(x, n) = (1/π) ∫_hemisphere(n) V_D(x, ω) (ω·n) dω        in [0, 1], 1 = open sky
//
// estimated with `samples` cosine-weighted directions per point (Malley's method: uniform
// points on the unit disk lifted to the hemisphere, so AO = unblocked rays / samples).
// V_D(x, ω) = 1 when the ray from x along ω hits no triangle closer than `distance` (a hard
// cut-off, Cycles' world.light_settings.distance; no falloff). Triangles are two-sided: a ray
// stops at a leaf from either side, whatever the winding.
//
// Sampling: each point gets the same low-discrepancy set (a Fibonacci lattice on [0,1)², mapped
// to the cosine-weighted hemisphere around an orthonormal basis built from n with the branchless
// construction of Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 6(1), 2017),
// shifted by a Cranley–Patterson rotation seeded from hash(key, seed), the key being the
// point's vertex id when it names one (OwnPrimitives::vertex_ids) and its row index otherwise.
// So every point's estimate is unbiased, stratified, and depends only on (its key, seed, its
// own data): never on the thread count, the block split or other points, and a vertex gets the
// same rays however its mesh's vertices are split into calls. No rand(), no global state.
//
// Origins (docs/DESIGN.md, 'Baselines and references' and 'Rays against Cycles' samples'):
// skip only what the receiver starts on, as Cycles does. A receiver may name the triangles it
// lies on (OwnPrimitives): a vertex of the tracer's mesh or a triangle (a texel's).
//
// A vertex, when the tracer was built with vertex normals, is started where Cycles' own vertex
// bake starts it ("Cycles' bake point"; Blender 3.x–5.x, kernel integrator_init_from_bake and
// shadow_ray_offset). Every triangle using the vertex is one of its corners (one corner per
// polygon when the polygons are known, BakeShading); its rays are dealt to the corners in turn
// (ray s to corner s mod k) — k × samples rays in all, as Cycles bakes every corner with its
// full sample count (RayTraceOptions::per_corner). A polygon's corner is baked where Blender's
// bake puts it: on the first triangle holding it in the polygon's triangulation *as the bake
// computes it* (without the face normal), at that triangle's vertex slot j, which Cycles then
// evaluates on triangle i of its own list (the mesh's cached triangulation: the tracer's
// triangles) at slot j. On a quad whose two triangulations differ (Blender's quad-flip test
// with and without the face normal disagrees on a quad with two coincident corners, a branch
// tip Sapling collapses) one corner is so baked at the quad's fourth vertex. A corner whose
// triangle starts with a zero edge (its first vertex coincides with another) has a NaN face
// normal in Cycles, and so has every ray direction, which nothing stops: it counts as open
// (1.0). Every other corner starts at Cycles' own bake point: the vertex moved towards the
// corner triangle's centroid by min(distance to the centroid, 1e-4 × max(1, largest
// |coordinate| of the vertex)) — Cycles' bake_offset_towards_center; it depends on the distance
// from the world origin, as Cycles' does (1.2 mm for a vertex 12 m from it) — and projected
// back onto the triangle in Cycles' float arithmetic, each 2 × 2 determinant one fused
// multiply-subtract (on a sliver that lands anywhere along it, often within rounding of an
// edge). A corner whose triangle's last two vertices coincide (a *residue* corner) is baked as
// Cycles bakes it: its face normal is the rounding residue of Cycles' fused cross product
// (e_a·e_b − fl(e_a·e_b) per component, e the repeated edge: a direction at random), and where
// that opposes the smooth normal the corner is backfacing, as Cycles shades it: both flip and
// the hemisphere turns into the surface. A residue of exactly 0 (every product exact) is
// Cycles' NaN normal again: open. For each traced corner:
//  - the hemisphere is around the smooth normal interpolated there from the triangle's three
//    vertex normals (its corner normals when given, BakeShading), the face normal taken on its
//    side (where a vertex normal opposes its face,
//    which Blender's own normals never do, Cycles would bake the other hemisphere);
//  - only the corner's triangle is skipped; a ray within cos⁻¹(0.1) of grazing the face (Cycles'
//    default shadow-terminator geometry offset, 0.1) starts lifted onto the smooth surface the
//    vertex normals describe (Cycles' shadow_ray_smooth_surface_offset), and one that dives below
//    the face keeps its own triangle as an occluder;
//  - a ray that skips its triangle but would miss it by Cycles' own edge test (its start within
//    rounding of an edge) leaves from Cycles' ray_offset instead, int(256 × the face normal)
//    float spacings per coordinate (0.5 mm at 20 units from the origin): Cycles'
//    integrate_surface_ray_offset, which Blender 3.4 and later apply to AO rays;
//  - the scene is built ROBUST, as Cycles builds it: its hit test also counts a face through
//    the ray's start (t = 0), so a start lying in another face's plane sees that face.
// A vertex with no corner (only collinear faces of zero area with distinct corners) starts
// 1e-4 × max(1, largest |coordinate|) off it along its normal and skips nothing. Measured on
// Sapling's collapsed branch tips (docs/DESIGN.md, 'Rays against Cycles' samples'): residue
// corners cut the error to Cycles' 1024 samples at the Douglas fir's 4,372 vertices on one from
// 0.129 to 0.038, and at its 1,791 tips (every face a residue one) from 0.121 to 0.042.
// A texel (triangle_ids) on such a tracer starts at the texel itself with its own normal,
// skips its triangle and gets the same terminator lift and ray offset; a texel on its
// triangle's boundary (a barycentric below 1e-5, Cycles' own floor: a conservative texel's
// closest point, on an edge or a vertex such as a UV sphere's pole) first moves towards the
// centroid by the bake reach, as a vertex's corner does, so no face meeting there stops it. Checked against Cycles
// (bench/probes/cycles_contact_probe.py, bench/cycles_contact.py, tests/blender/test_bake_point.py;
// 1024 samples): a vertex of a branch piece lying 25–90 µm from another piece's face, an
// isolated square tube (1.0 where a start inside a face without the lift gives 0.85–0.89), a
// trunk's capped rim in the ground (0.130 against 0.129).
//
// A vertex or a triangle on a tracer without vertex normals skips all its own triangles
// (every triangle using that vertex, or that triangle: an Embree filter on the primitive id) and
// starts on the surface itself, moved a hair (1e-3 of the way, at least the float spacing of the
// coordinates, at most half) towards the centroid of one own triangle: a texel's, or of a
// vertex's triangles the one facing its normal most squarely (so the start stays on the surface,
// not inside the solid a convex corner bounds). That puts it strictly on its own side of any
// surface it touches (the ground under a root, the branch under a leaf) without crossing
// anything farther away. Rays go from t = 0. Checked against Cycles' own vertex bake (Blender
// 3.4, 1024 samples): blade roots on the ground leaning either way and the top ring of a capped
// trunk agree within 0.004; the base ring of a trunk whose bottom cap lies in the ground plane
// reads 0.167 where Cycles gives 0.128. The old normal offset gave 1.0, 0.71 and 0.83 there.
//
// A receiver without own primitives (an arbitrary point, or offset ≥ 0 given explicitly)
// starts at x + offset · n̂ instead. offset < 0 (the default) means automatic: 1e-5 × the
// scene's bounding-box diagonal + 1e-6 × the largest absolute vertex coordinate (float
// precision of the hit test, which grows with the extent and with the distance from the
// origin). A leaf's own vertex therefore does not see its own triangle, but such an offset also
// skips a surface the point lies on whenever the normal leans into it, and misses occluders
// nearer than it along the normal: name the own primitives where they are known.
//
// Edge cases (measured, never NaN, never a crash — docs/DESIGN.md, 'How we check ourselves'):
//  - empty mesh (0 triangles, any vertex count including 0): nothing occludes, AO = 1 everywhere;
//  - zero-length normal: no hemisphere is defined; AO = 1 (documented fallback);
//  - normals need not be unit length: they are normalised;
//  - non-finite vertex, point or normal coordinates: std::invalid_argument;
//  - triangle index outside [0, V): std::invalid_argument;
//  - an own vertex id outside [0, V) or own triangle id outside [0, M) (other than −1 = none):
//    std::invalid_argument;
//  - samples < 1 (or a point's own count), distance ≤ 0 or NaN, offset NaN:
//    std::invalid_argument;
//  - a failure reported by Embree (out of memory, ...): canopy_ao::Error with Embree's message.
//
// Bent normals (docs/DESIGN.md, 'Bent normals'): on request, each point's cosine-weighted mean
// unoccluded direction, normalised, in world space:
//
//     B(x, n) = normalize( ∫_hemisphere(n) V_D(x, ω) ω (ω·n) dω )
//
// estimated from the same cosine-weighted rays as the AO (the sum of the unblocked rays'
// directions; the cosine weighting is in their distribution), so AO and bent normal are one
// trace. Fallbacks: every ray blocked (no open direction) → the unit surface normal; zero-length
// normal (no hemisphere) → (0, 0, 0); an empty scene → the unit normal (nothing blocks).
//
// Opacity (docs/DESIGN.md, 'Opacity of leaf cards'): a tracer may be given each triangle's
// material and UVs and each material's alpha (a constant, or a float texture looked up
// bilinearly with wrap, as Blender's Image Texture with Linear interpolation and Repeat
// extension). A hit on a surface of alpha a in (0, 1) stops the ray with probability a: the
// ray goes on unless a hash of (ray origin, ray direction, triangle), taken as a number in
// [0, 1), is below a. A ray through surfaces of alphas a_i is then open with probability
// Π(1 − a_i), Cycles' transparent-shadow throughput on its AO ray, so the AO's expectation is
// Cycles' (a uniform card of alpha 0.5 over a plane: 0.505 in Cycles); the decision depends
// only on the ray and the triangle, so it is the same whatever the thread count, and the same
// when Embree reports one hit twice. alpha ≤ 0 never stops a ray, alpha ≥ 1 always does.
// Every ray honours it (bake, calibration, buried test, bent normals, texels): it is in the
// occlusion filter. Instanced meshes (Prototype) stay opaque.
//
// Thread safety: a built RayTracer is immutable; ao() may be called from several threads at
// once. Work inside one call runs on all cores (canopy_ao::parallel_for_blocks, capped by
// set_max_threads); the BVH build honours the same cap.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao {

/// Names the rule by which vertex receivers start at Cycles' bake point ("Origins" above), so
/// that AO cached from an earlier rule is recognised as stale (the benchmarks' reference caches
/// key on it; Python: `_core.TRACER_RULE`). Change it with the rule.
inline constexpr const char* kTracerRule =
    "bake-point-per-corner-bake-split-cycles-projection-self-offset";

// === Options
/// Each point's cosine-weighted sample set. Measured on Sapling Tree Gen trees (MAE against a
/// 4096-ray reference, bench/bench_sampling.py): the lattice is as good as the Owen-scrambled
/// Sobol' net at 16 rays and 1–6 % better at 64–256; both cut the error of independent rays
/// by 15–40 % at 16 rays (figures in bench/README.md).
enum class Sampling {
  /// The shared Fibonacci lattice, Cranley–Patterson-rotated per point (the default; above).
  kLattice,
  /// Owen-scrambled Sobol' (0, 2)-sequence, hashed per point (Burley, "Practical Hash-based
  /// Owen Scrambling", JCGT 9(4), 2020): stratified in every elementary interval at 2^k rays,
  /// and any prefix of a point's rays is itself well spread.
  kSobol,
  /// Independent uniform rays (a counter-based hash per point and ray): the baseline.
  kIndependent,
};

/// Per-call settings of the ray-traced AO. Defaults match the Python API.
struct RayTraceOptions {
  /// Cosine-weighted rays per point (≥ 1). The standard error at AO = a is at most
  /// sqrt(a(1−a)/samples) (independent rays); stratification does much better on smooth
  /// occluders: measured RMS error at 1024 samples 0.0008 (half-plane edge, binomial 0.016)
  /// and 0.0014 (sphere 30° off the normal, binomial 0.007); at 64 samples 0.013 and 0.011.
  int samples = 64;
  /// AO distance D in scene units (> 0; +inf = unlimited): occluders farther than D along a ray
  /// do not count (Cycles' world.light_settings.distance, a hard cut-off).
  float distance = std::numeric_limits<float>::infinity();
  /// Seed of the per-point rotations. Same seed → bit-identical results; another seed → other
  /// noise with the same expectation.
  std::uint32_t seed = 0;
  /// Ray origin offset along the normal, scene units (≥ 0), or < 0 for automatic (see above:
  /// the own-surface start where own primitives are given, else the automatic normal offset).
  float offset = -1.0f;
  /// Which sample set (see Sampling; all unbiased, deterministic, thread-count independent).
  Sampling sampling = Sampling::kLattice;
  /// A vertex started at Cycles' bake point ("Origins" above) casts `samples` rays per corner,
  /// as Cycles' bake takes its sample count at every face corner: k corners, one set of k ×
  /// samples directions dealt out to them in turn. False deals `samples` rays out to the corners
  /// (k times fewer rays; docs/DESIGN.md, 'Rays against Cycles' samples'). Other receivers have
  /// one start and cast `samples` either way. A vertex casts at most max(samples, 65,536) rays.
  bool per_corner = true;
  /// Per-point sample counts (N entries, each ≥ 1, taking `samples`' place point by point), or
  /// null: every point takes `samples`. The add-on's vertex bakes give every vertex the same
  /// rays whatever its corners (per_corner false; docs/DESIGN.md, 'Rays against Cycles'
  /// samples').
  const std::int32_t* point_samples = nullptr;
  /// Consecutive points that form one receiver (≥ 1): a texel's anti-aliasing sub-samples.
  /// Point i (its row in the call) is slot i mod g of group i / g; its count is the group's:
  /// one set of max(count, g) directions keyed by the group, dealt out to its points in turn
  /// (the point casts rays slot, slot + g, slot + 2g, ...), so the texel casts its count in
  /// all and the points' mean is one stratified estimate over its footprint. A point with a
  /// vertex id keeps its own set. Calls must not split a group (the row index decides it).
  int point_group = 1;
};

/// The primitives each receiver lies on (see "Origins" above). Either pointer may be null (no
/// receiver has one); otherwise it holds one int32 per query point, −1 = none:
///  - vertex_ids[i]: an index into the tracer's vertices; every triangle using it is skipped;
///  - triangle_ids[i]: an index into the tracer's triangles; that triangle is skipped.
/// Both may be given for the same point (the union is skipped; the vertex sets the start).
struct OwnPrimitives {
  const std::int32_t* vertex_ids = nullptr;
  const std::int32_t* triangle_ids = nullptr;
};

/// How the Embree scene is built (tuning, not semantics: results are the same up to float
/// rounding at triangle edges, and at a ray's start, where ROBUST counts a face through it).
struct RayTracerBuildOptions {
  /// RTC_BUILD_QUALITY_HIGH (spatial splits: slower build, faster traversal) instead of MEDIUM.
  bool high_quality = false;
  /// RTC_SCENE_FLAG_ROBUST (watertight-safe traversal; costs about a third of the speed,
  /// docs/DESIGN.md, 'Facts measured in Blender'). Always on for a tracer built with vertex
  /// normals (Cycles' bake point, "Origins" above).
  bool robust = false;
};

/// A mesh placed many times by Instance (an instanced tree): #V by 3 vertices, #M by 3 vertex
/// indices in [0, V), as the RayTracer's own mesh.
struct Prototype {
  PointsView vertices;
  const std::int32_t* triangles = nullptr;
  std::size_t triangle_count = 0;
};

/// One placement of a Prototype: `matrix` is the row-major 4 × 4 world-from-prototype
/// transform (affine: last row 0 0 0 1; any scale, rotation, shear or mirroring).
struct Instance {
  std::uint32_t prototype = 0;
  float matrix[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
};

/// What vertex receivers need to start at Cycles' bake point (see "Origins" above).
struct BakeShading {
  /// The mesh's #V by 3 vertex normals (need not be unit length; a zero normal stands for its
  /// triangles' face normal), or size 0: vertex receivers keep the other rule.
  PointsView vertex_normals;
  /// #M polygon ids, or null: triangles with the same id are one polygon (a quad's two), and a
  /// vertex has one corner per polygon, on the polygon's first triangle using it (Blender bakes
  /// each face corner once); null makes every triangle a corner.
  const std::int32_t* polygons = nullptr;
  /// #M by 3 by 3 corner (split) normals, row 3i + j triangle i's corner j, or null: each
  /// corner then takes its vertex's normal. Cycles evaluates a face corner with that corner's
  /// own normal (the face normal on a flat face, split at sharp edges, custom normals where
  /// set), the terminator lift included (none on a flat face: all three equal the face
  /// normal); a texel's lift too. Need not be unit length; a zero normal stands for its
  /// triangle's face normal.
  /// Needs vertex_normals. Equal to the vertex normals, the AO is bit for bit the same.
  const float* corner_normals = nullptr;
};

/// One material's alpha (1 = opaque, 0 = transparent; raytrace.h, "Opacity").
struct AlphaMaterial {
  /// The alpha of an untextured material (used when `texture` is null).
  float alpha = 1.0f;
  /// `height` rows of `width` alphas, row 0 at v = 0 (Blender's image pixel order), or null.
  /// Looked up bilinearly at (u·width − ½, v·height − ½), wrapped (Repeat).
  const float* texture = nullptr;
  int width = 0;
  int height = 0;
  /// A texture's alpha is offset + scale · t, t the interpolated texel value, decoded from
  /// sRGB first when `srgb` (Cycles interpolates an 8-bit sRGB image's encoded values and
  /// decodes the result).
  bool srgb = false;
  float scale = 1.0f;
  float offset = 0.0f;
  /// The texel the UV falls in, not interpolated (Blender's Closest interpolation).
  bool nearest = false;
};

/// Which triangles are not opaque (raytrace.h, "Opacity"). Copied by the constructor.
struct Opacity {
  /// #M entries: each triangle's index into `alphas`, −1 = opaque; or null: all opaque.
  const std::int32_t* materials = nullptr;
  /// #M by 6: each triangle's three corners' (u, v) in triangle order, or null (then every
  /// textured material is read at (0, 0)).
  const float* uvs = nullptr;
  std::vector<AlphaMaterial> alphas;
};

// === Ray tracer
/// An Embree scene of two-sided triangles, built once (expensive: reuse it for many queries).
class RayTracer {
 public:
  // === Constructor
  /// vertices: #V by 3 positions (packed xyz, finite); triangles: #M by 3 vertex indices in
  /// [0, V), row-major (`triangles[3*j + k]`). The data are copied: the arrays may be freed
  /// afterwards. M may be 0 (then AO = 1 everywhere).
  /// Throws std::invalid_argument on bad input, canopy_ao::Error if Embree fails.
  RayTracer(PointsView vertices, const std::int32_t* triangles, std::size_t triangle_count,
            const RayTracerBuildOptions& build = {});
  /// Same, plus instanced meshes (Embree instances, RTC_GEOMETRY_TYPE_INSTANCE): each
  /// prototype's BVH is built once, each instance places it by its matrix, so a forest of
  /// copies costs one tree's memory. Instanced triangles occlude like the own mesh's (two-sided,
  /// same AO) but carry no receivers: OwnPrimitives ids always refer to the own mesh. Throws
  /// std::invalid_argument for a bad prototype mesh, an instance's prototype outside
  /// [0, #prototypes), a non-finite or non-affine matrix.
  RayTracer(PointsView vertices, const std::int32_t* triangles, std::size_t triangle_count,
            const std::vector<Prototype>& prototypes, const std::vector<Instance>& instances,
            const RayTracerBuildOptions& build = {});
  /// Same, with what vertex receivers need to start at Cycles' bake point (BakeShading; above,
  /// "Origins"). Throws std::invalid_argument for normals of another size than #V or not
  /// finite, or polygons without normals.
  RayTracer(PointsView vertices, const std::int32_t* triangles, std::size_t triangle_count,
            const BakeShading& shading, const std::vector<Prototype>& prototypes,
            const std::vector<Instance>& instances, const RayTracerBuildOptions& build = {});
  /// Same, with each triangle's opacity (Opacity; raytrace.h, "Opacity"). Throws
  /// std::invalid_argument for a material index outside [−1, #alphas), a texture without
  /// pixels or a positive size, or a non-finite alpha or UV.
  RayTracer(PointsView vertices, const std::int32_t* triangles, std::size_t triangle_count,
            const BakeShading& shading, const Opacity& opacity,
            const std::vector<Prototype>& prototypes, const std::vector<Instance>& instances,
            const RayTracerBuildOptions& build = {});
  ~RayTracer();
  RayTracer(RayTracer&&) noexcept;
  RayTracer& operator=(RayTracer&&) noexcept;
  RayTracer(const RayTracer&) = delete;
  RayTracer& operator=(const RayTracer&) = delete;

  // === Methods
  /// AO at N query points with normals (each #N by 3), written to out[0..N). Normals need not
  /// be unit length; a zero normal gives 1. `out` must hold N floats.
  void ao(PointsView points, PointsView normals, const RayTraceOptions& options,
          float* out) const;
  /// Same, skipping each receiver's own primitives (OwnPrimitives: N entries per given array).
  void ao(PointsView points, PointsView normals, const OwnPrimitives& own,
          const RayTraceOptions& options, float* out) const;
  /// Same, also writing each point's bent normal (above, "Bent normals") to bent[3i..3i+3)
  /// when `bent` is not null (then it must hold 3N floats). The AO is the same as without it.
  void ao(PointsView points, PointsView normals, const OwnPrimitives& own,
          const RayTraceOptions& options, float* out, float* bent) const;
  /// Same, returning a new vector of N values in [0, 1].
  std::vector<float> ao(PointsView points, PointsView normals,
                        const RayTraceOptions& options = {}) const;
  /// AO at every vertex of the mesh itself (#V values), with the given #V by 3 vertex normals;
  /// each vertex is its own receiver (OwnPrimitives::vertex_ids = 0, 1, ..., V−1).
  std::vector<float> ao_at_vertices(PointsView normals, const RayTraceOptions& options = {}) const;

  /// The offset used when RayTraceOptions::offset < 0.
  float auto_offset() const;
  std::size_t vertex_count() const;
  std::size_t triangle_count() const;
  std::size_t instance_count() const;
  /// Whether some triangle is not opaque (built with an Opacity naming one).
  bool has_opacity() const;
  /// Whether vertex receivers start at Cycles' bake point (built with vertex normals).
  bool has_vertex_normals() const;
  /// The mean number of corners ("Origins" above) of the mesh's vertices: what per-corner rays
  /// (RayTraceOptions::per_corner) multiply a bake of every vertex's rays by. 1 without vertex
  /// normals or vertices; a vertex with no triangle with area counts 1.
  double corners_per_vertex() const;
  /// The rays a bake of vertices [first, first + count) casts at `samples` per corner (each
  /// vertex at Cycles' bake point, RayTraceOptions::per_corner): Σ min(k × samples, max(samples,
  /// 65,536)) over their corner counts k; count × samples without vertex normals. The cost
  /// model's counted work. Throws std::invalid_argument if the range is not in the mesh or
  /// samples < 1.
  std::uint64_t vertex_rays(std::size_t first, std::size_t count, int samples) const;
  /// Each of vertices [first, first + count)'s rays at one sample per corner — its corner count
  /// (at least 1; 1 each without vertex normals) — one entry per vertex: vertex_rays(v, 1, 1)
  /// for every v in one call. Throws std::invalid_argument if the range is not in the mesh.
  std::vector<std::int32_t> vertex_corners(std::size_t first, std::size_t count) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// === One-off
/// Builds a RayTracer and evaluates AO once (the build dominates for few points: keep a
/// RayTracer when calling repeatedly). Shapes and errors as RayTracer and RayTracer::ao.
std::vector<float> ao_raytrace(PointsView vertices, const std::int32_t* triangles,
                               std::size_t triangle_count, PointsView points, PointsView normals,
                               const RayTraceOptions& options = {});

}  // namespace canopy_ao
