// Canopy AO — float images and their files (OpenImageIO).
//
// Row order: row 0 is the BOTTOM of the image (v = 0), as in Blender's `Image.pixels` and in
// texel_raster.h. Files store their top row first, so write_image/read_image flip rows by
// default (bottom_up = true): an image written here and loaded into Blender shows v = 1 at the
// top, and read_image returns the same row order it was given.
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

namespace canopy_ao {

// === Types
/// A float image, H×W×C interleaved (channel fastest), row 0 = bottom (v = 0).
struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;  ///< width * height * channels values

  float& at(int x, int y, int c = 0) {
    return pixels[(static_cast<std::size_t>(y) * width + x) * channels + c];
  }
  float at(int x, int y, int c = 0) const {
    return pixels[(static_cast<std::size_t>(y) * width + x) * channels + c];
  }
};

/// How pixels are stored in the file.
enum class PixelType {
  Auto,    ///< by extension: .exr → Float, .png → UInt16, .tga → UInt8, anything else → Float
  Float,   ///< 32-bit float (EXR, TIFF); exact round trip
  Half,    ///< 16-bit float (EXR)
  UInt16,  ///< 16-bit unsigned, [0, 1] ↦ 0..65535, values outside clamped (PNG, TIFF)
  UInt8,   ///< 8-bit unsigned (PNG, TGA, TIFF); TGA holds nothing finer (its 16-bit mode is
           ///< 5-5-5-1 colour)
};

// === Options
struct ImageWriteOptions {
  PixelType type = PixelType::Auto;
  /// true: pixels[0] is the bottom row (Blender's order) and rows are flipped on write.
  bool bottom_up = true;
  /// (name, value) string attributes stored in the file's header (an EXR header attribute, a
  /// PNG text chunk): what read_image_attributes returns. Names are plain identifiers (letters,
  /// digits, '_'), so no format treats them as its own ("oiio:", "openexr:", ...); values are
  /// non-empty and hold no NUL (std::invalid_argument otherwise).
  std::vector<std::pair<std::string, std::string>> attributes;
};

// === Functions
/// Writes an H×W×C float image (C in 1..4; 1 = grey "Y", 3 = RGB, 4 = RGBA) to `path`, the
/// format chosen by the extension (.exr, .png, .tif, ... anything OpenImageIO writes).
/// PRE: pixels holds width*height*channels floats.
/// Throws std::invalid_argument for bad sizes or a pixel type the format cannot hold (PNG
/// float, EXR integer, TGA anything but uint8), canopy_ao::Error naming the path and OpenImageIO's message when the
/// file cannot be created or written (missing folder, no permission, unknown extension).
void write_image(const std::string& path, const float* pixels, int width, int height,
                 int channels, const ImageWriteOptions& options = {});
void write_image(const std::string& path, const Image& image,
                 const ImageWriteOptions& options = {});

/// Reads the first subimage of `path` as float (integer formats scaled to [0, 1]), all its
/// channels. bottom_up = true returns row 0 = bottom (the file's last row).
/// Throws canopy_ao::Error naming the path and OpenImageIO's message on failure.
Image read_image(const std::string& path, bool bottom_up = true);

/// Every string attribute of the first subimage's header, (name, value), in the file's order
/// (the ones write_image stored, and any the format or another program put there). Reads the
/// header only. Throws canopy_ao::Error naming the path and OpenImageIO's message on failure.
std::vector<std::pair<std::string, std::string>> read_image_attributes(const std::string& path);

/// Which pixel type `Auto` resolves to for `path` (by extension, case-insensitive).
PixelType default_pixel_type(const std::string& path);

}  // namespace canopy_ao
