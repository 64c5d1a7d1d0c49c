// Canopy AO — Python bindings for per-texel baking: UV rasterisation (TexelSet), splat with
// margin dilation, and OpenImageIO image files.
//
// Arrays cross without copies both ways: inputs are read in place (GIL released while the core
// runs), results are numpy views of the C++ vectors, kept alive by the object that owns them.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "arrays.h"
#include "canopy_ao/image_io.h"
#include "canopy_ao/texel_raster.h"

namespace canopy_ao::py_bind {

namespace {

// A per-corner array: (3M, d) or (M, 3, d) float32, C-contiguous. Returns M.
std::size_t corners_arg(const py::array& a, const char* name, py::ssize_t d, bool check_finite) {
  require_dtype(a, name, py::dtype::of<float>(), "float32");
  const bool flat = a.ndim() == 2 && a.shape(1) == d && a.shape(0) % 3 == 0;
  const bool grouped = a.ndim() == 3 && a.shape(1) == 3 && a.shape(2) == d;
  if (!flat && !grouped) {
    std::ostringstream s;
    s << name << " must have shape (3*M, " << d << ") or (M, 3, " << d
      << "), one row per triangle corner, got " << shape_str(a);
    throw py::value_error(s.str());
  }
  const std::size_t m = flat ? std::size_t(a.shape(0)) / 3 : std::size_t(a.shape(0));
  if (check_finite) {
    const float* p = static_cast<const float*>(a.data());
    for (std::size_t i = 0; i < 3 * m * std::size_t(d); ++i) {
      if (!std::isfinite(p[i])) {
        std::ostringstream s;
        s << name << " has a non-finite value (NaN or inf) at corner " << i / d << " (triangle "
          << i / d / 3 << ")";
        throw py::value_error(s.str());
      }
    }
  }
  return m;
}

std::pair<int, int> resolution_arg(const py::object& o) {
  // operator.index accepts Python and numpy integers, refuses floats.
  const py::object index = py::module_::import("operator").attr("index");
  long long w = 0, h = 0;
  try {
    if (py::hasattr(o, "__index__")) {
      w = h = index(o).cast<long long>();
    } else {
      const py::tuple t = py::module_::import("builtins").attr("tuple")(o);
      if (t.size() != 2) throw py::value_error("");
      w = index(t[0]).cast<long long>();
      h = index(t[1]).cast<long long>();
    }
  } catch (const py::error_already_set&) {
    throw py::value_error("resolution must be an int or (width, height) of ints, got " +
                          std::string(py::repr(o)));
  } catch (const py::value_error&) {
    throw py::value_error("resolution must be an int or (width, height) of ints, got " +
                          std::string(py::repr(o)));
  }
  if (w < 1 || w > 16384 || h < 1 || h > 16384) {
    throw py::value_error("resolution must be 1..16384 in each direction, got " +
                          std::to_string(w) + " x " + std::to_string(h));
  }
  return {int(w), int(h)};
}

// A path reaches the file system byte for byte as Python would pass it to open(): str through
// os.fsencode (the file-system encoding, surrogateescape: non-UTF-8 names round-trip), bytes and
// os.PathLike as they are. Refused (ValueError): other types, an empty path, an embedded NUL
// (C strings would cut the name there).
std::string path_arg(const py::object& p) {
  py::object b;
  try {
    b = py::module_::import("os").attr("fsencode")(p);
  } catch (const py::error_already_set& e) {
    throw py::value_error("path must be a str, bytes or os.PathLike, got " +
                          std::string(py::repr(p)));
  }
  const std::string s = b.cast<std::string>();
  if (s.empty()) throw py::value_error("path must not be empty");
  if (s.find('\0') != std::string::npos) {
    throw py::value_error("path must not contain a NUL character, got " +
                          std::string(py::repr(p)));
  }
  return s;
}

// A read-only numpy view of a vector owned by `owner` (a Python object kept alive as its base).
template <class T>
py::array view_of(const std::vector<T>& v, std::vector<py::ssize_t> shape, py::handle owner,
                  py::dtype dtype = py::dtype::of<T>()) {
  if (v.empty()) return py::array(dtype, shape);
  py::array a(dtype, shape, {}, v.data(), owner);
  a.attr("flags").attr("writeable") = false;
  return a;
}

// A numpy array taking over a vector's buffer (no copy).
template <class T>
py::array adopt(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
  auto* heap = new std::vector<T>(std::move(v));
  py::capsule owner(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array(py::dtype::of<T>(), shape, {}, heap->data(), owner);
}

py::object splat_to_numpy(TexelImage&& r, bool grey, bool return_mask) {
  const py::ssize_t H = r.image.height, W = r.image.width, C = r.image.channels;
  std::vector<py::ssize_t> shape = grey ? std::vector<py::ssize_t>{H, W}
                                        : std::vector<py::ssize_t>{H, W, C};
  py::array image = adopt(std::move(r.image.pixels), shape);
  if (!return_mask) return image;
  return py::make_tuple(image, adopt(std::move(r.mask), {H, W}));
}

// values (T,) or (T, C); returns C, with grey = values were 1-D.
int values_arg(const py::array& a, std::size_t count, bool* grey) {
  // (checked below: dtype, shape, then every value finite)
  require_dtype(a, "values", py::dtype::of<float>(), "float32");
  const bool ok = (a.ndim() == 1 || (a.ndim() == 2 && a.shape(1) >= 1 && a.shape(1) <= 4)) &&
                  std::size_t(a.shape(0)) == count;
  if (!ok) {
    std::ostringstream s;
    s << "values must have shape (" << count << ",) or (" << count << ", C) with C in 1..4, got "
      << shape_str(a);
    throw py::value_error(s.str());
  }
  *grey = a.ndim() == 1;
  const int channels = a.ndim() == 1 ? 1 : int(a.shape(1));
  const float* v = static_cast<const float*>(a.data());
  for (std::size_t i = 0; i < count * std::size_t(channels); ++i) {
    if (!std::isfinite(v[i])) {
      throw py::value_error("values has a non-finite value (NaN or inf) at texel " +
                            std::to_string(i / channels));
    }
  }
  return channels;
}

int margin_arg(const py::object& margin) {
  return static_cast<int>(int_arg(margin, "margin", 0, 1 << 15));
}

py::object splat(const std::int32_t* pixels, std::size_t count, const py::array& values, int w,
                 int h, int margin, double background, bool return_mask) {
  if (!(std::fabs(background) <= 3.4e38)) {
    throw py::value_error("background must be a finite float32 number, got " +
                          num_str(background));
  }
  bool grey = true;
  const int channels = values_arg(values, count, &grey);
  const float* v = static_cast<const float*>(values.data());
  TexelImage r;
  {
    py::gil_scoped_release release;
    r = splat_texels(pixels, v, count, channels, w, h, margin, background);
  }
  return splat_to_numpy(std::move(r), grey, return_mask);
}

const char* kRasterizeDoc = R"doc(
Rasterises a triangulated mesh's UV layout: one receiver point per covered texel.

Arguments (one row per triangle corner — Blender's loop order — so seams and split normals work):
  uvs        float32 (3*M, 2) or (M, 3, 2): texture coordinates. Non-finite or |uv| > 64:
             the triangle is skipped (counted in stats["invalid_uv"]).
  positions  float32 (3*M, 3) or (M, 3, 3): world positions, finite.
  normals    float32, same shape, finite; or None: the face normal (corners 0, 1, 2,
             right-handed).
  resolution int or (width, height), each 1..16384.
  conservative  also emit texels the triangle touches whose centre lies in no triangle (their
             point is the triangle's nearest point; `exact` is False), so UV islands thinner
             than a texel are never lost.

Texel (i, j) has its centre at uv = ((i + 0.5) / width, (j + 0.5) / height); row 0 is the bottom
(v = 0) as in Blender's Image.pixels, pixel index = j * width + i. A texel whose centre lies on a
shared edge or vertex belongs to exactly one triangle (top-left fill rule on UVs snapped to 1/256
texel). Returns a TexelSet; evaluate any AO function on its positions/normals, then
TexelSet.splat(values). Releases the GIL.
)doc";

const char* kSplatDoc = R"doc(
Puts per-texel values into an image and dilates a margin.

  pixels     int32 (T,): pixel indices j * width + i (row 0 = bottom), each in the image.
  values     float32 (T,) or (T, C) with C in 1..4, finite. A pixel given twice keeps the later.
  resolution int or (width, height).
  margin     texels to grow every island by (ring by ring, each new texel the mean of its
             already-filled 8-neighbours); covered texels are never changed. Default 16, as
             Blender's bake margin.
  background value of texels neither covered nor within the margin (default 1.0 = open sky,
             harmless if it ever bleeds into a multiplied AO).
  return_mask  also return the coverage mask uint8 (H, W): 0 background, 1 covered, 2 margin.

Returns float32 (H, W) for 1-D values, (H, W, C) otherwise; row 0 = bottom (v = 0), so
`image.ravel()` is Blender's Image.pixels order for a one-channel layout. Releases the GIL.
)doc";

}  // namespace

void bind_texel(py::module_& m) {
  py::class_<TexelSet>(m, "TexelSet",
                       "Covered texels of a UV layout, ascending pixel index: the receiver points "
                       "of a per-texel bake. Array attributes are read-only views (no copy).")
      .def_property_readonly("width", [](const TexelSet& t) { return t.width; })
      .def_property_readonly("height", [](const TexelSet& t) { return t.height; })
      .def_property_readonly(
          "resolution", [](const TexelSet& t) { return py::make_tuple(t.width, t.height); },
          "(width, height)")
      .def("__len__", &TexelSet::size)
      .def_property_readonly(
          "pixels",
          [](py::object self) {
            const auto& t = self.cast<const TexelSet&>();
            return view_of(t.pixels, {py::ssize_t(t.size())}, self);
          },
          "int32 (T,): pixel index j * width + i, row 0 = bottom (v = 0)")
      .def_property_readonly(
          "positions",
          [](py::object self) {
            const auto& t = self.cast<const TexelSet&>();
            return view_of(t.positions, {py::ssize_t(t.size()), 3}, self);
          },
          "float32 (T, 3): world position at the texel centre (barycentric interpolation)")
      .def_property_readonly(
          "normals",
          [](py::object self) {
            const auto& t = self.cast<const TexelSet&>();
            return view_of(t.normals, {py::ssize_t(t.size()), 3}, self);
          },
          "float32 (T, 3): unit interpolated corner normal (the face normal if it vanishes, "
          "(0, 0, 1) if the face has no area either)")
      .def_property_readonly(
          "barycentrics",
          [](py::object self) {
            const auto& t = self.cast<const TexelSet&>();
            return view_of(t.barycentrics, {py::ssize_t(t.size()), 3}, self);
          },
          "float32 (T, 3): weights of the triangle's corners 0, 1, 2 (to interpolate other "
          "corner attributes)")
      .def_property_readonly(
          "triangles",
          [](py::object self) {
            const auto& t = self.cast<const TexelSet&>();
            return view_of(t.triangles, {py::ssize_t(t.size())}, self);
          },
          "int32 (T,): the triangle each texel samples")
      .def_property_readonly(
          "exact",
          [](py::object self) {
            const auto& t = self.cast<const TexelSet&>();
            return view_of(t.exact, {py::ssize_t(t.size())}, self, py::dtype::of<bool>());
          },
          "bool (T,): True = texel centre inside the triangle, False = conservative texel")
      .def_property_readonly(
          "overlapping_texels", [](const TexelSet& t) { return t.stats.overlapping_texels; },
          "texel centres inside two or more triangles (overlapping UVs: warn the user)")
      .def_property_readonly(
          "degenerate", [](const TexelSet& t) { return t.stats.degenerate; },
          "triangles skipped for zero UV area")
      .def_property_readonly(
          "stats",
          [](const TexelSet& t) {
            py::dict d;
            d["triangles"] = t.stats.triangles;
            d["degenerate"] = t.stats.degenerate;
            d["invalid_uv"] = t.stats.invalid_uv;
            d["exact_texels"] = t.stats.exact_texels;
            d["conservative_texels"] = t.stats.conservative_texels;
            d["overlapping_texels"] = t.stats.overlapping_texels;
            return d;
          },
          "dict: triangles, degenerate, invalid_uv, exact_texels, conservative_texels, "
          "overlapping_texels")
      .def(
          "splat",
          [](const TexelSet& t, const py::array& values, const py::object& margin,
             double background, bool return_mask) {
            return splat(t.pixels.data(), t.size(), values, t.width, t.height, margin_arg(margin),
                         background, return_mask);
          },
          py::arg("values"), py::arg("margin") = 16, py::arg("background") = 1.0f,
          py::arg("return_mask") = false,
          "splat_texels(self.pixels, values, self.resolution, ...): values float32 (T,) or "
          "(T, C) -> image (H, W) or (H, W, C), row 0 = bottom.")
      .def("__repr__", [](const TexelSet& t) {
        std::ostringstream s;
        s << "<TexelSet " << t.width << "x" << t.height << ": " << t.size() << " texels ("
          << t.stats.conservative_texels << " conservative), " << t.stats.overlapping_texels
          << " overlapping, " << t.stats.degenerate << " degenerate>";
        return s.str();
      });

  m.def(
      "rasterize_uv",
      [](const py::array& uvs, const py::array& positions, const py::object& normals,
         const py::object& resolution, bool conservative) {
        const std::size_t n = corners_arg(uvs, "uvs", 2, false);
        const std::size_t np = corners_arg(positions, "positions", 3, true);
        if (np != n) {
          throw py::value_error("uvs and positions must describe the same triangles, got " +
                                std::to_string(n) + " and " + std::to_string(np));
        }
        const float* nrm = nullptr;
        py::array normals_array;
        if (!normals.is_none()) {
          if (!py::isinstance<py::array>(normals)) {
            throw py::value_error("normals must be a float32 numpy array or None");
          }
          normals_array = normals.cast<py::array>();
          if (corners_arg(normals_array, "normals", 3, true) != n) {
            throw py::value_error("uvs and normals must describe the same triangles");
          }
          nrm = static_cast<const float*>(normals_array.data());
        }
        const auto [w, h] = resolution_arg(resolution);
        CornerTriangles tris{static_cast<const float*>(uvs.data()),
                             static_cast<const float*>(positions.data()), nrm, n};
        RasterOptions o;
        o.width = w;
        o.height = h;
        o.conservative = conservative;
        TexelSet t;
        {
          py::gil_scoped_release release;
          t = rasterize_uv(tris, o);
        }
        return t;
      },
      py::arg("uvs"), py::arg("positions"), py::arg("normals") = py::none(),
      py::arg("resolution") = 1024, py::arg("conservative") = true, kRasterizeDoc);

  m.def(
      "splat_texels",
      [](const py::array& pixels, const py::array& values, const py::object& resolution,
         const py::object& margin, double background, bool return_mask) {
        require_dtype(pixels, "pixels", py::dtype::of<std::int32_t>(), "int32");
        if (pixels.ndim() != 1) {
          throw py::value_error("pixels must have shape (T,), got " + shape_str(pixels));
        }
        const auto [w, h] = resolution_arg(resolution);
        return splat(static_cast<const std::int32_t*>(pixels.data()),
                     std::size_t(pixels.shape(0)), values, w, h, margin_arg(margin), background,
                     return_mask);
      },
      py::arg("pixels"), py::arg("values"), py::arg("resolution"), py::arg("margin") = 16,
      py::arg("background") = 1.0f, py::arg("return_mask") = false, kSplatDoc);

  m.def(
      "dilate_margin",
      [](py::array image, py::array mask, const py::object& margin_value) {
        const int margin = margin_arg(margin_value);
        require_dtype(image, "image", py::dtype::of<float>(), "float32");
        require_dtype(mask, "mask", py::dtype::of<std::uint8_t>(), "uint8");
        if (!image.writeable() || !mask.writeable()) {
          throw py::value_error("image and mask must be writeable (they are changed in place)");
        }
        if (image.ndim() < 2 || image.ndim() > 3 || mask.ndim() != 2 ||
            mask.shape(0) != image.shape(0) || mask.shape(1) != image.shape(1)) {
          throw py::value_error("image must be (H, W) or (H, W, C) and mask (H, W), got " +
                                shape_str(image) + " and " + shape_str(mask));
        }
        const int h = int(image.shape(0)), w = int(image.shape(1));
        const int c = image.ndim() == 3 ? int(image.shape(2)) : 1;
        float* px = static_cast<float*>(image.mutable_data());
        std::uint8_t* mk = static_cast<std::uint8_t*>(mask.mutable_data());
        py::gil_scoped_release release;
        dilate_margin(px, mk, w, h, c, margin);
      },
      py::arg("image"), py::arg("mask"), py::arg("margin"),
      "Grows the covered area (mask != 0) of image float32 (H, W[, C]) by `margin` texels in "
      "place, ring by ring; new texels take the mean of their filled 8-neighbours and get mask 2. "
      "Covered texels never change.");

#ifndef CANOPY_AO_NO_IMAGE_IO  // the portable build has no OpenImageIO (docs/PORTABILITY.md)
  m.def(
      "write_image",
      [](const py::object& path, const py::array& pixels, const std::string& dtype,
         bool bottom_up, const py::object& attributes) {
        const std::string p = path_arg(path);
        ImageWriteOptions o;
        if (!attributes.is_none()) {
          if (!py::isinstance<py::dict>(attributes)) {
            throw py::value_error("attributes must be a dict of str to str, got " +
                                  std::string(py::str(py::type::of(attributes).attr("__name__"))));
          }
          for (const auto& kv : attributes.cast<py::dict>()) {
            if (!py::isinstance<py::str>(kv.first) || !py::isinstance<py::str>(kv.second)) {
              throw py::value_error("attributes must map str to str, got " +
                                    std::string(py::repr(kv.first)) + ": " +
                                    std::string(py::repr(kv.second)));
            }
            o.attributes.emplace_back(kv.first.cast<std::string>(), kv.second.cast<std::string>());
          }
        }
        require_dtype(pixels, "pixels", py::dtype::of<float>(), "float32");
        if (pixels.ndim() < 2 || pixels.ndim() > 3 ||
            (pixels.ndim() == 3 && (pixels.shape(2) < 1 || pixels.shape(2) > 4)) ||
            pixels.shape(0) < 1 || pixels.shape(1) < 1) {
          throw py::value_error("pixels must have shape (H, W) or (H, W, C) with C in 1..4, got " +
                                shape_str(pixels));
        }
        o.bottom_up = bottom_up;
        if (dtype == "auto") o.type = PixelType::Auto;
        else if (dtype == "float") o.type = PixelType::Float;
        else if (dtype == "half") o.type = PixelType::Half;
        else if (dtype == "uint16") o.type = PixelType::UInt16;
        else if (dtype == "uint8") o.type = PixelType::UInt8;
        else {
          throw py::value_error("dtype must be 'auto', 'float', 'half', 'uint16' or 'uint8', got '" +
                                dtype + "'");
        }
        const int h = int(pixels.shape(0)), w = int(pixels.shape(1));
        const int c = pixels.ndim() == 3 ? int(pixels.shape(2)) : 1;
        const float* data = static_cast<const float*>(pixels.data());
        // Every value must survive the file's type: finite, and within half's range for "half"
        // (beyond ±65504 it would be stored as inf).
        const float limit = o.type == PixelType::Half ? 65504.0f : 3.4028235e38f;
        for (std::size_t i = 0; i < std::size_t(h) * w * c; ++i) {
          if (!(std::fabs(data[i]) <= limit)) {
            throw py::value_error("pixels has the value " + num_str(data[i]) + " at index " +
                                  std::to_string(i) +
                                  (o.type == PixelType::Half
                                       ? ", outside half's range +-65504"
                                       : " (NaN or inf): images must be finite"));
          }
        }
        py::gil_scoped_release release;
        write_image(p, data, w, h, c, o);
      },
      py::arg("path"), py::arg("pixels"), py::arg("dtype") = "auto", py::arg("bottom_up") = true,
      py::arg("attributes") = py::none(),
      R"doc(
Writes float32 pixels (H, W) or (H, W, C), C in 1..4 (1 = grey "Y", 3 = RGB, 4 = RGBA), with
OpenImageIO; the format follows the extension. dtype "auto": .exr → 32-bit float, .png → 16-bit
(values in [0, 1], clamped), .tga → 8-bit, others → float; or "float", "half" (EXR), "uint16",
"uint8" (the only one TGA holds).
bottom_up=True: row 0 is the bottom (Blender's order), flipped on write so the file shows v = 1
at the top. Raises CanopyAOError naming the path and OpenImageIO's message if the file cannot be
written, ValueError for bad shapes, non-finite pixels (or beyond +-65504 for "half") or a dtype
the format cannot hold. The path (str, bytes or os.PathLike) reaches the file system byte for
byte (os.fsencode); an empty path or one with a NUL is a ValueError. attributes: {name: value}
strings stored in the header (EXR header attributes, PNG text), read back by
read_image_attributes; names are letters, digits and '_' (anything else, or an empty value or
a NUL in one, is a ValueError). Releases the GIL.
)doc");

  m.def(
      "read_image",
      [](const py::object& path, bool bottom_up) {
        const std::string p = path_arg(path);
        Image img;
        {
          py::gil_scoped_release release;
          img = read_image(p, bottom_up);
        }
        return adopt(std::move(img.pixels), {img.height, img.width, img.channels});
      },
      py::arg("path"), py::arg("bottom_up") = true,
      "Reads an image as float32 (H, W, C) (integer formats scaled to [0, 1]); bottom_up=True "
      "returns row 0 = bottom, the order write_image takes. Raises CanopyAOError naming the path "
      "if it cannot be read.");

  m.def(
      "read_image_attributes",
      [](const py::object& path) {
        const std::string p = path_arg(path);
        const auto attrs = without_gil([&] { return read_image_attributes(p); });
        // A header is another program's data: bytes that are not UTF-8 must not raise.
        const auto text = [](const std::string& b) {
          return py::reinterpret_steal<py::str>(
              PyUnicode_DecodeUTF8(b.data(), py::ssize_t(b.size()), "replace"));
        };
        py::dict d;
        for (const auto& [name, value] : attrs) d[text(name)] = text(value);
        return d;
      },
      py::arg("path"),
      "{name: value} of every string attribute in the image's header (what write_image's "
      "attributes stored, and any other program's); reads the header only. Raises "
      "CanopyAOError naming the path if it cannot be read.");
#endif
}

}  // namespace canopy_ao::py_bind
