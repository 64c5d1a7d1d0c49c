// Canopy AO — per-texel baking: rasterise a mesh's UV layout into receiver points, then put
// per-texel values back into an image with a dilated margin.
//
//   rasterize_uv  triangles (per face-corner UV, position, normal) → TexelSet: one receiver
//                 point per covered texel (pixel index, world position, world normal), which any
//                 AO method evaluates like ordinary vertices;
//   splat_texels  per-texel values → image (+ coverage mask);
//   dilate_margin grows the covered area N texels outward so mip-maps and filtering never mix
//                 in the background.
//
// Conventions
//  - Texel (i, j) — column i, row j — has its centre at uv = ((i + 0.5) / W, (j + 0.5) / H).
//    Row 0 is the BOTTOM (v = 0), Blender's image convention; pixel index = j * W + i.
//  - UVs are snapped to 1/256 texel (fixed point, as GPUs do) and coverage is decided with exact
//    integer edge functions and the top-left fill rule: a texel whose centre lies on an edge
//    shared by two triangles (bit-identical UVs) is covered by exactly one of them, and a vertex
//    shared by a fan once. Mirrored (clockwise) UV triangles rasterise like the others.
//  - Conservative coverage: a texel whose square the triangle touches but whose centre lies in
//    no triangle gets the nearest point of the nearest touching triangle (clamped barycentrics,
//    ties → lower triangle id), so islands thinner than a texel still produce texels. Such
//    texels are flagged (exact = 0) so tests can count centre coverage separately.
//  - Overlapping UVs: a texel whose centre lies in two or more triangles keeps the lowest
//    triangle id and is counted in RasterStats::overlapping_texels so the add-on can warn.
//    With the fill rule, triangles that merely share an edge or vertex never count.
//  - Only UVs in [-64, 64] are rasterised (the 0..1 tile is the image; UDIM-style offsets up to
//    64 are tolerated but land outside it); triangles with other or non-finite UVs are skipped
//    and counted, as are zero-area (in snapped UV) triangles.
//  - Deterministic: output order is ascending pixel index and does not depend on threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "canopy_ao/image_io.h"

namespace canopy_ao {

// === Input
/// M triangles given corner by corner (face-corner / "loop" data, so UV seams and split normals
/// survive): corner k of triangle t is row 3t + k of each array.
struct CornerTriangles {
  const float* uvs = nullptr;        ///< 3M × 2 texture coordinates (u, v)
  const float* positions = nullptr;  ///< 3M × 3 world positions
  const float* normals = nullptr;    ///< 3M × 3 world normals, or nullptr: the face normal
  std::size_t count = 0;             ///< M, number of triangles
};

// === Options
struct RasterOptions {
  int width = 1024;          ///< image width in texels, 1..16384
  int height = 1024;         ///< image height in texels, 1..16384
  bool conservative = true;  ///< also emit texels touched by a triangle but centred outside
};

// === Results
struct RasterStats {
  std::size_t triangles = 0;            ///< M, as given
  std::size_t degenerate = 0;           ///< zero UV area after snapping: skipped
  std::size_t invalid_uv = 0;           ///< non-finite UV or |u|,|v| > 64: skipped
  std::size_t exact_texels = 0;         ///< texels whose centre lies in a triangle
  std::size_t conservative_texels = 0;  ///< texels only touched (exact = 0)
  std::size_t overlapping_texels = 0;   ///< texel centres inside ≥ 2 triangles
};

/// One receiver point per covered texel, ascending pixel index. T = size().
struct TexelSet {
  int width = 0;
  int height = 0;
  std::vector<std::int32_t> pixels;     ///< T, j * width + i, row 0 = bottom
  std::vector<std::int32_t> triangles;  ///< T, the triangle the texel samples
  std::vector<float> barycentrics;      ///< T × 3, weights of that triangle's corners 0, 1, 2
  std::vector<float> positions;         ///< T × 3, world position (barycentric interpolation)
  std::vector<float> normals;           ///< T × 3, normalised interpolated normal (see below)
  std::vector<std::uint8_t> exact;      ///< T, 1 = centre inside the triangle, 0 = conservative
  RasterStats stats;

  std::size_t size() const { return pixels.size(); }
};

/// Coverage mask values (one byte per pixel, same layout as the image).
enum TexelCoverage : std::uint8_t {
  kTexelEmpty = 0,    ///< background
  kTexelCovered = 1,  ///< a texel of the TexelSet
  kTexelMargin = 2,   ///< filled by dilate_margin
};

/// A splatted image and its coverage mask (width * height bytes, TexelCoverage).
struct TexelImage {
  Image image;
  std::vector<std::uint8_t> mask;
};

// === Functions
/// Rasterises every triangle's UVs into a width × height grid and interpolates position and
/// normal at each covered texel. The normal is the normalised barycentric mix of the corner
/// normals; where that mix vanishes (opposite corner normals) or no normals are given, the
/// face normal of the positions (corner order 0, 1, 2, right-handed) — (0, 0, 1) if the face
/// has no area either, so every normal is unit length (normalised without overflow or
/// underflow, geometry.h normalize).
/// PRE: arrays hold 3 * count rows; positions/normals finite (checked at the Python boundary).
/// Throws std::invalid_argument for a resolution outside 1..16384 or null arrays with count > 0.
TexelSet rasterize_uv(const CornerTriangles& triangles, const RasterOptions& options);

/// Writes values (T × channels, one row per texel) into a width × height × channels image at
/// the given pixel indices; all other pixels get `background`. If a pixel appears twice, the
/// later value wins. Then dilates the margin (dilate_margin) by `margin` texels.
/// Throws std::invalid_argument for a pixel outside the image, a non-finite value, channels
/// outside 1..4, a resolution outside 1..16384 or a negative margin.
TexelImage splat_texels(const std::int32_t* pixels, const float* values, std::size_t count,
                        int channels, int width, int height, int margin,
                        float background = 1.0f);

/// Grows the covered area ring by ring, `margin` times: each empty pixel (mask 0) with a filled
/// 8-neighbour (mask ≠ 0, filled before this ring) takes the average of those neighbours and is
/// marked kTexelMargin. After it, every empty pixel within Chebyshev distance `margin` of a
/// covered one is filled; covered pixels are never changed.
/// PRE: mask.size() == width*height, image.pixels.size() == width*height*channels.
void dilate_margin(Image& image, std::vector<std::uint8_t>& mask, int margin);
/// Same on raw buffers (for the Python binding, which owns the arrays).
void dilate_margin(float* pixels, std::uint8_t* mask, int width, int height, int channels,
                   int margin);

}  // namespace canopy_ao
