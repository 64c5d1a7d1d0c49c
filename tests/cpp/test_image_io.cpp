// OpenImageIO round trips and error reporting. Files go to a fresh temporary folder.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>

#include "canopy_ao/geometry.h"
#include "canopy_ao/image_io.h"

using namespace canopy_ao;
namespace fs = std::filesystem;

namespace {

class ImageIO : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::string tmpl = (fs::temp_directory_path() / "canopy_ao_image_XXXXXX").string();
    dir_ = mkdtemp(tmpl.data());
    ASSERT_FALSE(dir_.empty());
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static std::string path(const std::string& name) { return (fs::path(dir_) / name).string(); }

  static Image random_image(int w, int h, int c, float lo, float hi, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> U(lo, hi);
    Image img;
    img.width = w, img.height = h, img.channels = c;
    img.pixels.resize(std::size_t(w) * h * c);
    for (float& v : img.pixels) v = U(rng);
    return img;
  }
  static fs::path dir_;
};
fs::path ImageIO::dir_;

}  // namespace

TEST_F(ImageIO, ExrFloatRoundTripIsExact) {
  for (int c : {1, 3, 4}) {
    const Image img = random_image(37, 23, c, -2.f, 5.f, 11 + c);
    const std::string p = path("float_" + std::to_string(c) + ".exr");
    write_image(p, img);
    const Image back = read_image(p);
    EXPECT_EQ(back.width, 37);
    EXPECT_EQ(back.height, 23);
    EXPECT_EQ(back.channels, c);
    EXPECT_EQ(back.pixels, img.pixels);  // bit-exact
  }
}

TEST_F(ImageIO, RowZeroIsTheBottomOfTheFile) {
  Image img;
  img.width = 2, img.height = 3, img.channels = 1;
  img.pixels = {0, 0, 1, 1, 2, 2};  // rows 0 (bottom), 1, 2 (top)
  const std::string p = path("rows.exr");
  write_image(p, img);
  const Image top_down = read_image(p, /*bottom_up=*/false);
  EXPECT_EQ(top_down.pixels, (std::vector<float>{2, 2, 1, 1, 0, 0}));
  ImageWriteOptions o;
  o.bottom_up = false;
  write_image(p, img, o);
  EXPECT_EQ(read_image(p, false).pixels, img.pixels);
}

TEST_F(ImageIO, HalfExrWithinHalfPrecision) {
  const Image img = random_image(16, 16, 1, 0.f, 1.f, 5);
  const std::string p = path("half.exr");
  ImageWriteOptions o;
  o.type = PixelType::Half;
  write_image(p, img, o);
  const Image back = read_image(p);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) {
    EXPECT_NEAR(back.pixels[i], img.pixels[i], 1e-3f * std::max(1.f, img.pixels[i]));
  }
}

TEST_F(ImageIO, Png16RoundTripWithinOneStep) {
  for (int c : {1, 3}) {
    Image img = random_image(29, 31, c, 0.f, 1.f, 21 + c);
    img.pixels[0] = 0.f;
    img.pixels[1] = 1.f;
    const std::string p = path("p16_" + std::to_string(c) + ".png");
    write_image(p, img);
    const Image back = read_image(p);
    ASSERT_EQ(back.channels, c);
    ASSERT_EQ(back.pixels.size(), img.pixels.size());
    for (std::size_t i = 0; i < img.pixels.size(); ++i) {
      EXPECT_NEAR(back.pixels[i], img.pixels[i], 1.0f / 65535) << i;
    }
    EXPECT_EQ(back.pixels[0], 0.f);
    EXPECT_EQ(back.pixels[1], 1.f);
  }
}

TEST_F(ImageIO, UnwritablePathNamesThePath) {
  const Image img = random_image(4, 4, 1, 0.f, 1.f, 1);
  const std::string p = path("no_such_folder/ao.exr");
  try {
    write_image(p, img);
    FAIL() << "expected canopy_ao::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
  const std::string q = path("ao.not_an_image_format");
  try {
    write_image(q, img);
    FAIL() << "expected canopy_ao::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(q), std::string::npos) << e.what();
  }
}

TEST_F(ImageIO, MissingFileNamesThePath) {
  const std::string p = path("missing.exr");
  try {
    read_image(p);
    FAIL() << "expected canopy_ao::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
}

TEST_F(ImageIO, FormatAndTypeMismatchIsBadInput) {
  const Image img = random_image(4, 4, 1, 0.f, 1.f, 1);
  ImageWriteOptions o;
  o.type = PixelType::Float;
  EXPECT_THROW(write_image(path("f.png"), img, o), std::invalid_argument);
  o.type = PixelType::UInt16;
  EXPECT_THROW(write_image(path("u.exr"), img, o), std::invalid_argument);
  Image five = random_image(2, 2, 1, 0.f, 1.f, 1);
  five.channels = 5;
  five.pixels.resize(20);
  EXPECT_THROW(write_image(path("five.exr"), five), std::invalid_argument);
  EXPECT_EQ(default_pixel_type("A.PNG"), PixelType::UInt16);
  EXPECT_EQ(default_pixel_type("a.exr"), PixelType::Float);
  // TGA: 8 bits or nothing (OpenImageIO would store 16-bit or float pixels as 8 bits).
  for (PixelType t : {PixelType::UInt16, PixelType::Float, PixelType::Half}) {
    o.type = t;
    EXPECT_THROW(write_image(path("t.tga"), img, o), std::invalid_argument);
  }
  EXPECT_FALSE(fs::exists(path("t.tga")));
  EXPECT_EQ(default_pixel_type("a.TGA"), PixelType::UInt8);
}

TEST_F(ImageIO, Tga8RoundTripWithinHalfAStep) {
  const Image img = random_image(7, 5, 1, 0.f, 1.f, 4);
  write_image(path("grey.tga"), img);  // Auto: uint8
  const Image back = read_image(path("grey.tga"));
  ASSERT_EQ(back.width, 7);
  ASSERT_EQ(back.height, 5);
  ASSERT_EQ(back.channels, 1);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) {
    EXPECT_NEAR(back.pixels[i], img.pixels[i], 0.5f / 255.f + 1e-6f) << i;
  }
}

TEST_F(ImageIO, HeaderAttributesRoundTripInExrAndPng) {
  const Image img = random_image(5, 4, 1, 0.f, 1.f, 3);
  for (const char* name : {"attrs.exr", "attrs.png"}) {
    ImageWriteOptions o;
    o.attributes = {{"canopy_ao", "{\"owner\": \"Tree.001\"}"}, {"note_2", "Baum \xc3\xa4"}};
    write_image(path(name), img, o);
    const auto got = read_image_attributes(path(name));
    for (const auto& want : o.attributes) {
      EXPECT_NE(std::find(got.begin(), got.end(), want), got.end()) << name << " " << want.first;
    }
  }
  ImageWriteOptions bad;
  bad.attributes = {{"openexr:x", "v"}};  // a format's own namespace: refused, nothing written
  EXPECT_THROW(write_image(path("bad.exr"), img, bad), std::invalid_argument);
  EXPECT_FALSE(fs::exists(path("bad.exr")));
  EXPECT_THROW(read_image_attributes(path("missing.exr")), Error);
}
