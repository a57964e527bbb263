#include "workspace/image_io.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/errors.h"
#include "tests/test_util.h"

namespace perf {
namespace {

Image Gradient(int w, int h, int c) {
  Image img(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) img.at(x, y, k) = 0.6f * x / w + 0.3f * y / h + 0.05f * k;
  return img;
}

void ExpectNear(const Image& a, const Image& b, float tol) {
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  ASSERT_EQ(a.channels, b.channels);
  for (size_t i = 0; i < a.pixels.size(); ++i) ASSERT_NEAR(a.pixels[i], b.pixels[i], tol) << "at " << i;
}

struct FormatCase {
  const char* ext;
  PixelFormat format;
  float tol;
};

class ImageRoundTrip : public ::testing::TestWithParam<FormatCase> {};

TEST_P(ImageRoundTrip, WritesAndReadsBack) {
  test::TempDir dir;
  const FormatCase fc = GetParam();
  const Image img = Gradient(37, 23, 3);
  const auto path = dir / (std::string("img") + fc.ext);
  WriteImage(path, img, fc.format);
  ImageInfo info;
  const Image back = ReadImage(path, &info);
  EXPECT_EQ(info.width, 37);
  EXPECT_EQ(info.height, 23);
  ExpectNear(img, back, fc.tol);
  const ImageInfo header = ReadImageInfo(path);
  EXPECT_EQ(header.width, 37);
  EXPECT_EQ(header.channels, 3);
  // Nothing but the file itself is left behind (the temporary was renamed).
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()), {}), 1);
}

INSTANTIATE_TEST_SUITE_P(Formats, ImageRoundTrip,
                         ::testing::Values(FormatCase{".png", PixelFormat::kUInt8, 0.51f / 255},
                                           FormatCase{".png", PixelFormat::kUInt16, 0.51f / 65535},
                                           FormatCase{".tif", PixelFormat::kUInt16, 0.51f / 65535},
                                           FormatCase{".exr", PixelFormat::kHalf, 1e-3f},
                                           FormatCase{".jpg", PixelFormat::kUInt8, 0.1f}));

TEST(ImageIo, ReportsStoredFormat) {
  test::TempDir dir;
  WriteImage(dir / "a.png", Gradient(8, 8, 3), PixelFormat::kUInt16);
  ImageInfo info;
  ReadImage(dir / "a.png", &info);
  EXPECT_EQ(info.format, PixelFormat::kUInt16);
}

TEST(ImageIo, RgbaComesBackPremultiplied) {
  test::TempDir dir;
  Image rgba(2, 1, 4);
  // Associated colour 0.25 with alpha 0.5 (straight colour 0.5).
  for (int c = 0; c < 3; ++c) rgba.at(0, 0, c) = 0.25f;
  rgba.at(0, 0, 3) = 0.5f;
  rgba.at(1, 0, 3) = 1.f;
  WriteImage(dir / "a.png", rgba, PixelFormat::kUInt16);
  const Image back = ReadImage(dir / "a.png");
  ASSERT_EQ(back.channels, 4);
  EXPECT_NEAR(back.at(0, 0, 0), 0.25f, 1e-3f);
  EXPECT_NEAR(back.at(0, 0, 3), 0.5f, 1e-3f);
}

TEST(ImageIo, ResizeKeepsConstantsAndMeans) {
  Image flat(64, 48, 3);
  std::fill(flat.pixels.begin(), flat.pixels.end(), 0.3f);
  const Image small = ResizeImage(flat, 16, 12);
  ASSERT_EQ(small.width, 16);
  ASSERT_EQ(small.height, 12);
  for (float v : small.pixels) EXPECT_NEAR(v, 0.3f, 1e-4f);

  Image checker(64, 64, 1);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) checker.at(x, y, 0) = ((x + y) % 2) ? 1.f : 0.f;
  const Image half = ResizeImage(checker, 8, 8);
  // A filtered downscale averages the 1-pixel checker to grey (a naive subsample would not).
  for (float v : half.pixels) EXPECT_NEAR(v, 0.5f, 0.02f);
}

TEST(ImageIo, MissingFileIsIoError) {
  test::TempDir dir;
  try {
    ReadImage(dir / "nope.png");
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("nope.png"), std::string::npos);
  }
}

TEST(ImageIo, GarbageFileIsInputErrorNamingIt) {
  test::TempDir dir;
  std::ofstream(dir / "bad.jpg") << "this is not a jpeg";
  try {
    ReadImageInfo(dir / "bad.jpg");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.jpg"), std::string::npos) << e.what();
  }
}

TEST(ImageIo, TruncatedPngIsInputError) {
  test::TempDir dir;
  WriteImage(dir / "a.png", Gradient(64, 64, 3), PixelFormat::kUInt8);
  const auto size = std::filesystem::file_size(dir / "a.png");
  std::filesystem::resize_file(dir / "a.png", size / 2);
  EXPECT_THROW(ReadImage(dir / "a.png"), InputError);
}

TEST(ImageIo, TruncatedJpegIsInputErrorNotGrey) {
  // libjpeg only warns ("premature end of data") and fills the rest with grey.
  test::TempDir dir;
  WriteImage(dir / "a.jpg", Gradient(64, 64, 3), PixelFormat::kUInt8);
  std::filesystem::resize_file(dir / "a.jpg", std::filesystem::file_size(dir / "a.jpg") / 2);
  try {
    ReadImage(dir / "a.jpg");
    FAIL() << "a truncated JPEG was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("a.jpg"), std::string::npos) << e.what();
  }
}

TEST(ImageIo, HugeHeaderIsRefusedBeforeDecoding) {
  test::TempDir dir;
  WriteImage(dir / "wide.png", Image(70000, 1, 1), PixelFormat::kUInt8);  // tiny file, 70000 wide
  try {
    ReadImageInfo(dir / "wide.png");
    FAIL() << "a 70000-pixel side was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("size = 70000x1x1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadImage(dir / "wide.png"), InputError);
}

TEST(ImageIo, KnowsImageExtensions) {
  EXPECT_TRUE(HasImageExtension("a/b/IMG_001.JPG"));
  EXPECT_TRUE(HasImageExtension("x.exr"));
  EXPECT_FALSE(HasImageExtension("cameras.bin"));
  EXPECT_FALSE(HasImageExtension("notes.txt"));
}

}  // namespace
}  // namespace perf
