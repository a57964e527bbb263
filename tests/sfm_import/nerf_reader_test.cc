// NeRF transforms.json reader: every bad intrinsic, number or matrix is refused with an
// InputError naming the file and the field; paths are resolved without opening anything.
#include "sfm_import/nerf_reader.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "common/errors.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

constexpr char kFrame[] =
    R"("frames": [{"file_path": "./train/r_0", "transform_matrix": [[1,0,0,0.5],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}])";

// A transforms.json with the given top-level fields before "frames".
std::string Json(const std::string& fields) { return "{" + fields + (fields.empty() ? "" : ", ") + kFrame + "}"; }

// Reads `text` as a file through the path overload: "" if it reads, else the InputError's field
// (checking that the message names the file).
std::string FieldOfError(const std::string& text) {
  test::TempDir dir;
  const fs::path path = dir / "transforms.json";
  std::ofstream(path, std::ios::binary) << text;
  try {
    ReadNerfTransforms(path);
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    return e.field().empty() ? "(none)" : e.field();
  }
  return "";
}

TEST(NerfReader, GoodFileReads) {
  EXPECT_EQ(FieldOfError(Json(R"("camera_angle_x": 0.69)")), "");
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": 500, "fl_y": 510, "cx": 400, "cy": 300, "w": 800, "h": 600.0)")), "");
}

TEST(NerfReader, FocalLengthsMustBePositive) {
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": 0)")), "fl_x");
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": -500)")), "fl_x");
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": 500, "fl_y": 0)")), "fl_y");
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": 500, "fl_y": -1e-9)")), "fl_y");
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": "500")")), "fl_x");
}

TEST(NerfReader, ImageSizeMustBeAWholeNumberOfPixels) {
  for (const char* w : {"-800", "0", "800.5", "1e20", "65537", "true"}) {
    EXPECT_EQ(FieldOfError(Json(StrCat(R"("fl_x": 500, "w": )", w))), "w") << w;
    EXPECT_EQ(FieldOfError(Json(StrCat(R"("fl_x": 500, "w": 800, "h": )", w))), "h") << w;
  }
  EXPECT_EQ(FieldOfError(Json(R"("fl_x": 500, "w": 65536, "h": 1)")), "");
}

TEST(NerfReader, FieldOfViewMustBeBetweenZeroAndPi) {
  for (const char* a : {"0", "-0.5", "3.1416", "40"}) {
    EXPECT_EQ(FieldOfError(Json(StrCat(R"("camera_angle_x": )", a))), "camera_angle_x") << a;
    EXPECT_EQ(FieldOfError(Json(StrCat(R"("camera_angle_x": 0.7, "camera_angle_y": )", a))), "camera_angle_y") << a;
  }
}

TEST(NerfReader, NumbersBeyondDoubleAndSyntaxErrorsNameTheFile) {
  // nlohmann reports 1e400 as out_of_range, not parse_error: it escaped as a raw library error.
  EXPECT_EQ(FieldOfError(Json(R"("camera_angle_x": 1e400)")), "(none)");
  EXPECT_EQ(FieldOfError(Json(R"("camera_angle_x": -1e400)")), "(none)");
  EXPECT_EQ(FieldOfError(R"({"camera_angle_x": 0.7, "frames": [{"file_path": "a", "transform_matrix":
      [[1,0,0,1e999],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})"), "(none)");
  EXPECT_EQ(FieldOfError(R"({"camera_angle_x": 0.7, )"), "(none)");
  EXPECT_EQ(FieldOfError(R"({"camera_angle_x": NaN})"), "(none)");
  EXPECT_EQ(FieldOfError(""), "(none)");
}

TEST(NerfReader, TransformMustBeFourByFourFinite) {
  const auto with_matrix = [](const std::string& m) {
    return R"({"camera_angle_x": 0.7, "frames": [{"file_path": "a", "transform_matrix": )" + m + "}]}";
  };
  EXPECT_EQ(FieldOfError(with_matrix("[[1,0,0,0],[0,1,0,0],[0,0,1,0]]")), "");  // the 4th row may be left out
  EXPECT_EQ(FieldOfError(with_matrix("[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1],[0,0,0,1]]")),
            "frames[0].transform_matrix");
  EXPECT_EQ(FieldOfError(with_matrix("[[1,0,0,0],[0,1,0,0],[0,0,1,null],[0,0,0,1]]")), "frames[0].transform_matrix");
  EXPECT_EQ(FieldOfError(with_matrix("[[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]")), "frames[0].transform_matrix");
  EXPECT_EQ(FieldOfError(with_matrix("[[[[[[[[[[1]]]]]]]]]]")), "frames[0].transform_matrix");
}

TEST(NerfReader, IntrinsicsThatOverflowAreRefused) {
  test::TempDir dir;
  const fs::path path = dir / "transforms.json";
  // A field of view that parses (5e-324 > 0) but whose tangent underflows to 0: fx = inf.
  std::ofstream(path) << Json(R"("camera_angle_x": 5e-324)");
  const NerfTransforms t = ReadNerfTransforms(path);
  double fx, fy, cx, cy;
  try {
    t.Intrinsics(800, 800, path.string(), &fx, &fy, &cx, &cy);
    ADD_FAILURE() << "fx = " << fx;
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "camera_angle_x");
  }
  std::ofstream(path) << Json(R"("camera_angle_x": 0.7, "camera_angle_y": 5e-324, "fl_y": 500)");
  try {
    ReadNerfTransforms(path).Intrinsics(800, 800, path.string(), &fx, &fy, &cx, &cy);
    ADD_FAILURE() << "fy = " << fy;
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "camera_angle_y");  // fl_y counts only with fl_x
  }
  std::ofstream(path) << Json(R"("fl_x": 500, "cx": 1.7e308, "w": 10)");
  try {
    ReadNerfTransforms(path).Intrinsics(800, 800, path.string(), &fx, &fy, &cx, &cy);
    ADD_FAILURE() << "cx = " << cx;
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "cx");
  }
}

TEST(NerfReader, StreamOverloadResolvesPathsWithoutOpeningThem) {
  std::istringstream in(Json(R"("fl_x": 500, "w": 800, "h": 600)"));
  const NerfTransforms t = ReadNerfTransforms(in, "/nowhere/scene/transforms.json");
  ASSERT_EQ(t.frames.size(), 1u);
  EXPECT_EQ(t.frames[0].image_path, fs::path("/nowhere/scene/train/r_0.png"));
  EXPECT_EQ(t.width, 800);
  // Blender -> PERF camera frame: y and z flipped, the position kept.
  EXPECT_EQ(t.frames[0].world_from_cam(1, 1), -1);
  EXPECT_EQ(t.frames[0].world_from_cam(2, 3), 4);
  double fx, fy, cx, cy;
  t.Intrinsics(400, 300, "mem", &fx, &fy, &cx, &cy);  // half the json's size
  EXPECT_EQ(fx, 250);
  EXPECT_EQ(fy, 250);
  EXPECT_EQ(cx, 200);
}

TEST(NerfReader, LegoReadsThroughBothOverloads) {
  PERF_REQUIRE_DATA(lego, "lego");
  const fs::path json_path = lego / "transforms_train.json";
  const NerfTransforms a = ReadNerfTransforms(json_path);
  std::ifstream in(json_path);
  const NerfTransforms b = ReadNerfTransforms(in, json_path);
  ASSERT_FALSE(a.frames.empty());
  ASSERT_EQ(a.frames.size(), b.frames.size());
  EXPECT_EQ(a.camera_angle_x, b.camera_angle_x);
  for (size_t i = 0; i < a.frames.size(); ++i) {
    EXPECT_EQ(a.frames[i].image_path, b.frames[i].image_path);
    EXPECT_EQ(a.frames[i].world_from_cam, b.frames[i].world_from_cam);
  }
}

// Inputs the fuzzer (fuzz/nerf_json_fuzzer.cc) found a problem with: each is refused with an
// InputError, or reads with finite, positive focal lengths (the fuzzer's checks).
TEST(NerfReader, FuzzRegressionsReadOrAreRefused) {
  const fs::path dir = fs::path(PERF_SOURCE_DIR) / "fuzz/regressions/nerf_json";
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " not found";
  for (const auto& e : fs::directory_iterator(dir)) {
    std::ifstream in(e.path(), std::ios::binary);
    try {
      const NerfTransforms t = ReadNerfTransforms(in, "fuzz/transforms.json");
      double fx, fy, cx, cy;
      t.Intrinsics(t.width.value_or(800), t.height.value_or(800), "fuzz", &fx, &fy, &cx, &cy);
      EXPECT_TRUE(std::isfinite(fx) && fx > 0 && std::isfinite(fy) && fy > 0) << e.path();
      EXPECT_TRUE(std::isfinite(cx) && std::isfinite(cy)) << e.path();
    } catch (const InputError&) {
    }
  }
}

}  // namespace
}  // namespace perf
