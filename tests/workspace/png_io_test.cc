// perf_gpu's image I/O (png_io.h, image_ops.h AreaResize) against OpenImageIO's, which perf uses
// (image_io.h): the same floats from the same PNG files (8- and 16-bit; grey, grey + alpha, RGB,
// RGBA), PNGs that OpenImageIO reads back as it reads its own, the bad files refused by name, and
// the area-average downscale of perf_gpu's image pyramid.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "common/errors.h"
#include "tests/test_util.h"
#include "workspace/image_io.h"
#include "workspace/image_ops.h"
#include "workspace/png_io.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

Image Random(int w, int h, int c, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);  // some out of range: clamped on write
  Image im(w, h, c);
  for (float& v : im.pixels) v = u(rng);
  return im;
}

TEST(PngIo, ReadsWhatOpenImageIoReadsToTheBit) {
  test::TempDir dir;
  for (const int channels : {1, 2, 3, 4}) {
    for (const PixelFormat format : {PixelFormat::kUInt8, PixelFormat::kUInt16}) {
      SCOPED_TRACE(testing::Message() << channels << " channels, " << (format == PixelFormat::kUInt8 ? 8 : 16) << " bit");
      const fs::path path = dir / "oiio.png";
      WriteImage(path, Random(37, 23, channels, channels), format);  // OpenImageIO's writer
      ImageInfo want_info, got_info;
      const Image want = ReadImage(path, &want_info);
      const Image got = png::Read(path, &got_info);
      EXPECT_EQ(got.width, want.width);
      EXPECT_EQ(got.height, want.height);
      EXPECT_EQ(got.channels, want.channels);
      EXPECT_EQ(got.pixels, want.pixels) << "the very floats perf trains on";
      EXPECT_EQ(got_info.format, want_info.format);
      const ImageInfo header = png::ReadInfo(path);
      EXPECT_EQ(header.width, 37);
      EXPECT_EQ(header.channels, channels);
    }
  }
}

TEST(PngIo, WritesWhatOpenImageIoWould) {
  test::TempDir dir;
  for (const int channels : {1, 3, 4}) {
    for (const PixelFormat format : {PixelFormat::kUInt8, PixelFormat::kUInt16}) {
      SCOPED_TRACE(testing::Message() << channels << " channels, " << (format == PixelFormat::kUInt8 ? 8 : 16) << " bit");
      Image image = Random(29, 31, channels, 7 + channels);
      image.pixels[5] = std::nanf("");
      WriteImage(dir / "oiio.png", image, format);
      png::Write(dir / "libpng.png", image, format);
      // Both read back by OpenImageIO: the same quantised values (clamped, NaN to 0, rounded).
      EXPECT_EQ(ReadImage(dir / "libpng.png").pixels, ReadImage(dir / "oiio.png").pixels);
      EXPECT_EQ(ReadImage(dir / "libpng.png").pixels[5], 0.f);
    }
  }
  EXPECT_THROW(png::Write(dir / "float.png", Random(4, 4, 3, 1), PixelFormat::kFloat), InputError);
  EXPECT_FALSE(fs::exists(dir / "float.png"));
}

TEST(PngIo, RefusesBadFilesByName) {
  test::TempDir dir;
  const auto expect_input_error = [](const fs::path& path, const std::string& words) {
    try {
      png::Read(path);
      ADD_FAILURE() << "expected InputError for " << path;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path.string()), std::string::npos) << what;
      EXPECT_NE(what.find(words), std::string::npos) << what;
    }
  };
  std::ofstream(dir / "not.png") << "this is not a PNG file at all";
  expect_input_error(dir / "not.png", "not a PNG");
  // Cut short inside its pixels.
  WriteImage(dir / "whole.png", Random(64, 64, 3, 3), PixelFormat::kUInt8);
  std::ifstream in(dir / "whole.png", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(dir / "cut.png", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  expect_input_error(dir / "cut.png", "cannot decode");
  // A header claiming 70000 pixels a side (its checksum fixed up): refused before any decoding.
  std::string wide = bytes;
  wide[16] = 0, wide[17] = 1, wide[18] = 0x11, wide[19] = 0x70;  // IHDR width = 70000
  uint32_t crc = 0xffffffffu;
  for (size_t i = 12; i < 29; ++i) {  // the chunk's type and data
    crc ^= static_cast<unsigned char>(wide[i]);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  crc ^= 0xffffffffu;
  for (int k = 0; k < 4; ++k) wide[29 + k] = static_cast<char>(crc >> (24 - 8 * k));
  std::ofstream(dir / "wide.png", std::ios::binary) << wide;
  expect_input_error(dir / "wide.png", "header");
  EXPECT_THROW(png::Read(dir / "missing.png"), IoError);
}

TEST(AreaResize, AveragesTheSourcePixelsEachOutputPixelCovers) {
  Image im(4, 2, 1);
  for (int x = 0; x < 4; ++x) {
    im.at(x, 0, 0) = static_cast<float>(x);
    im.at(x, 1, 0) = static_cast<float>(10 * x);
  }
  const Image half = AreaResize(im, 2, 1);  // 2x2 blocks
  EXPECT_FLOAT_EQ(half.at(0, 0, 0), (0 + 1 + 0 + 10) / 4.f);
  EXPECT_FLOAT_EQ(half.at(1, 0, 0), (2 + 3 + 20 + 30) / 4.f);
  // 3 to 2: the middle source pixel is shared half and half.
  Image row(3, 1, 1);
  row.pixels = {3.f, 6.f, 9.f};
  const Image two = AreaResize(row, 2, 1);
  EXPECT_FLOAT_EQ(two.at(0, 0, 0), (3 * 1 + 6 * 0.5f) / 1.5f);
  EXPECT_FLOAT_EQ(two.at(1, 0, 0), (6 * 0.5f + 9 * 1) / 1.5f);
  // Any size down (a photo of 533 rows to 266): the mean is kept, a constant stays constant.
  const Image photo = Random(80, 533, 3, 11);
  const Image small = AreaResize(photo, 40, 266);
  double mean_in = 0, mean_out = 0;
  for (float v : photo.pixels) mean_in += v;
  for (float v : small.pixels) mean_out += v;
  EXPECT_NEAR(mean_out / small.pixels.size(), mean_in / photo.pixels.size(), 1e-5);
  Image flat(7, 5, 2);
  for (float& v : flat.pixels) v = 0.25f;
  for (float v : AreaResize(flat, 3, 2).pixels) EXPECT_NEAR(v, 0.25f, 1e-7);
  EXPECT_EQ(AreaResize(flat, 7, 5).pixels, flat.pixels);
}

}  // namespace
}  // namespace perf
