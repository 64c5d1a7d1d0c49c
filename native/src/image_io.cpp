#include "canopy_ao/image_io.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <stdexcept>
#include <string>

#include "canopy_ao/geometry.h"

namespace canopy_ao {
namespace {

std::string extension_of(const std::string& path) {
  const std::size_t slash = path.find_last_of("/\\");
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

OIIO::TypeDesc type_desc(PixelType t) {
  switch (t) {
    case PixelType::Half: return OIIO::TypeDesc::HALF;
    case PixelType::UInt16: return OIIO::TypeDesc::UINT16;
    case PixelType::UInt8: return OIIO::TypeDesc::UINT8;
    default: return OIIO::TypeDesc::FLOAT;
  }
}

const char* type_name(PixelType t) {
  switch (t) {
    case PixelType::Half: return "half";
    case PixelType::UInt16: return "uint16";
    case PixelType::UInt8: return "uint8";
    case PixelType::Float: return "float";
    default: return "auto";
  }
}

// OpenImageIO keeps the reason for a failed create/open in its global error, per-object errors
// for the rest; gather whichever is set.
std::string oiio_message(const OIIO::ImageOutput* out) {
  std::string msg = out ? out->geterror() : std::string();
  const std::string global = OIIO::geterror();
  if (!global.empty()) msg += (msg.empty() ? "" : "; ") + global;
  return msg.empty() ? "unknown OpenImageIO error" : msg;
}
std::string oiio_message(const OIIO::ImageInput* in) {
  std::string msg = in ? in->geterror() : std::string();
  const std::string global = OIIO::geterror();
  if (!global.empty()) msg += (msg.empty() ? "" : "; ") + global;
  return msg.empty() ? "unknown OpenImageIO error" : msg;
}

}  // namespace

PixelType default_pixel_type(const std::string& path) {
  const std::string ext = extension_of(path);
  if (ext == ".png") return PixelType::UInt16;
  if (ext == ".tga") return PixelType::UInt8;
  return PixelType::Float;
}

void write_image(const std::string& path, const float* pixels, int width, int height,
                 int channels, const ImageWriteOptions& options) {
  if (width < 1 || height < 1) {
    throw std::invalid_argument("write_image: image must be at least 1 x 1, got " +
                                std::to_string(width) + " x " + std::to_string(height));
  }
  if (channels < 1 || channels > 4) {
    throw std::invalid_argument("write_image: channels must be 1..4, got " +
                                std::to_string(channels));
  }
  if (pixels == nullptr) throw std::invalid_argument("write_image: no pixels");
  const std::string ext = extension_of(path);
  const PixelType type =
      options.type == PixelType::Auto ? default_pixel_type(path) : options.type;
  const bool integer = type == PixelType::UInt8 || type == PixelType::UInt16;
  if (ext == ".png" && !integer) {
    throw std::invalid_argument("write_image: PNG holds uint8 or uint16, not " +
                                std::string(type_name(type)) + " ('" + path + "')");
  }
  // OpenImageIO would write any other type to a TGA as 8 bits, silently.
  if (ext == ".tga" && type != PixelType::UInt8) {
    throw std::invalid_argument("write_image: TGA holds uint8 (its 16-bit mode is 5-5-5-1 "
                                "colour), not " + std::string(type_name(type)) + " ('" + path +
                                "')");
  }
  if (ext == ".exr" && integer) {
    throw std::invalid_argument("write_image: EXR holds float or half, not " +
                                std::string(type_name(type)) + " ('" + path + "')");
  }

  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    throw Error("cannot write image '" + path + "': no OpenImageIO writer for this file name (" +
                oiio_message(static_cast<const OIIO::ImageOutput*>(nullptr)) + ")");
  }
  OIIO::ImageSpec spec(width, height, channels, type_desc(type));
  // Single-channel files are luminance ("Y"), which Blender loads as a grey image.
  switch (channels) {
    case 1: spec.channelnames = {"Y"}; break;
    case 2: spec.channelnames = {"Y", "A"}; spec.alpha_channel = 1; break;
    case 3: spec.channelnames = {"R", "G", "B"}; break;
    default: spec.channelnames = {"R", "G", "B", "A"}; spec.alpha_channel = 3; break;
  }
  if (ext == ".exr") spec.attribute("compression", "zip");
  // The pixels are data, stored linearly: say so. OpenImageIO 3 otherwise tags an integer PNG
  // as sRGB (sRGB, gAMA 0.45455 and cHRM chunks), which viewers and engines would decode.
  if (ext == ".png") spec.attribute("oiio:ColorSpace", "Linear");
  for (const auto& [name, value] : options.attributes) {
    const bool plain = !name.empty() && std::all_of(name.begin(), name.end(), [](unsigned char c) {
      return std::isalnum(c) || c == '_';
    });
    if (!plain) {
      throw std::invalid_argument("write_image: attribute names are letters, digits and '_', "
                                  "got '" + name + "'");
    }
    // OpenEXR drops an empty string, and a NUL would cut the value short: refused, so what
    // read_image_attributes returns is what was given.
    if (value.empty() || value.find('\0') != std::string::npos) {
      throw std::invalid_argument("write_image: attribute '" + name + "' is empty or holds a "
                                  "NUL byte");
    }
    spec.attribute(name, value);
  }
  if (!out->open(path, spec)) {
    throw Error("cannot write image '" + path + "': " + oiio_message(out.get()));
  }
  const OIIO::stride_t xstride = OIIO::stride_t(sizeof(float)) * channels;
  const OIIO::stride_t row = xstride * width;
  // Bottom-up rows: start at the last row and walk backwards (a negative stride, no copy).
  const float* first = options.bottom_up ? pixels + std::size_t(height - 1) * width * channels
                                         : pixels;
  const OIIO::stride_t ystride = options.bottom_up ? -row : row;
  if (!out->write_image(OIIO::TypeDesc::FLOAT, first, xstride, ystride)) {
    const std::string msg = oiio_message(out.get());
    out->close();
    throw Error("cannot write image '" + path + "': " + msg);
  }
  if (!out->close()) {
    throw Error("cannot write image '" + path + "': " + oiio_message(out.get()));
  }
}

void write_image(const std::string& path, const Image& image, const ImageWriteOptions& options) {
  if (image.pixels.size() != std::size_t(image.width) * image.height * image.channels) {
    throw std::invalid_argument("write_image: pixel count does not match the image size");
  }
  write_image(path, image.pixels.data(), image.width, image.height, image.channels, options);
}

Image read_image(const std::string& path, bool bottom_up) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    throw Error("cannot read image '" + path + "': " +
                oiio_message(static_cast<const OIIO::ImageInput*>(nullptr)));
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.depth > 1) throw Error("cannot read image '" + path + "': volume images unsupported");
  Image img;
  img.width = spec.width;
  img.height = spec.height;
  img.channels = spec.nchannels;
  img.pixels.resize(std::size_t(img.width) * img.height * img.channels);
  const OIIO::stride_t xstride = OIIO::stride_t(sizeof(float)) * img.channels;
  const OIIO::stride_t row = xstride * img.width;
  float* first = bottom_up ? img.pixels.data() + std::size_t(img.height - 1) * img.width * img.channels
                           : img.pixels.data();
  if (!in->read_image(0, 0, 0, img.channels, OIIO::TypeDesc::FLOAT, first, xstride,
                      bottom_up ? -row : row)) {
    const std::string msg = oiio_message(in.get());
    in->close();
    throw Error("cannot read image '" + path + "': " + msg);
  }
  in->close();
  return img;
}

std::vector<std::pair<std::string, std::string>> read_image_attributes(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    throw Error("cannot read image '" + path + "': " +
                oiio_message(static_cast<const OIIO::ImageInput*>(nullptr)));
  }
  std::vector<std::pair<std::string, std::string>> out;
  for (const OIIO::ParamValue& p : in->spec().extra_attribs) {
    if (p.type() == OIIO::TypeDesc::STRING && p.nvalues() == 1) {
      out.emplace_back(p.name().string(), p.get_string());
    }
  }
  in->close();
  return out;
}

}  // namespace canopy_ao
