#include "workspace/scene.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "common/errors.h"
#include "tests/test_util.h"

namespace perf {
namespace {

Scene MakeScene() {
  Scene s;
  s.source = {"colmap", "/data/sparse/0", "/data/images", "binary", 2};
  s.background = {0.1, 0.2, 0.3};
  s.box.center = {0.1, -2.5, 1.0 / 3.0};
  s.box.size = {1.5, 2.25, 0.75};
  s.box.rotation = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  s.box.method = "test";
  s.shells.center = s.box.center;
  s.shells.radii = {2.0, 3.5, 7.25};
  SceneCamera c;
  c.id = 7;
  c.width = 400;
  c.height = 266;
  c.fx = 301.123456789012345;
  c.fy = 300.5;
  c.cx = 200.25;
  c.cy = 133.0 / 3.0;
  c.source = {"OPENCV", {600, 601, 400, 266, -0.126, 0.12, 1e-4, -2e-4}, 800, 533};
  s.cameras.push_back(c);
  for (int i = 0; i < 3; ++i) {
    SceneImage im;
    im.name = "dir/img_" + std::to_string(i) + ".jpg";
    im.path = "images/dir/img_" + std::to_string(i) + ".png";
    im.source_path = "/data/images/" + im.name;
    im.camera_id = 7;
    im.split = i == 0 ? Split::kTest : i == 2 ? Split::kExcluded : Split::kTrain;
    if (i == 2) im.excluded_because = "pose looks wrong: 18.2 units from the cameras' centre";
    if (i == 0) im.pose_doubt = "in a group that sees the object elsewhere: 5 photos";
    if (i == 1) im.turn_group = 2;
    im.world_from_cam.leftCols<3>() = Eigen::AngleAxisd(0.1 * i + 0.2, Eigen::Vector3d::UnitY()).toRotationMatrix();
    im.world_from_cam.col(3) = Eigen::Vector3d(i, 2.0 / 7.0, -1e-9);
    if (i == 1) {
      im.alpha_path = "alpha/dir/img_1.png";
      im.refined_world_from_cam = im.world_from_cam;
      im.refined_world_from_cam->col(3).x() += 0.125;
      im.refined_focal_scale = 1.0 + 1.0 / 3.0 / 100;
    }
    s.images.push_back(im);
  }
  return s;
}

TEST(Scene, JsonRoundTripIsExact) {
  const Scene s = MakeScene();
  const Scene back = SceneFromJson(SceneToJson(s), "scene.json");
  EXPECT_EQ(back.version, kSceneVersion);
  EXPECT_EQ(back.source.type, "colmap");
  EXPECT_EQ(back.source.downscale, 2);
  EXPECT_EQ(back.source.max_size, 0);
  EXPECT_EQ(back.background, s.background);
  EXPECT_EQ(back.box.center, s.box.center);
  EXPECT_EQ(back.box.size, s.box.size);
  EXPECT_EQ(back.box.rotation, s.box.rotation);
  EXPECT_EQ(back.shells.radii, s.shells.radii);
  ASSERT_EQ(back.cameras.size(), 1u);
  EXPECT_EQ(back.cameras[0].fx, s.cameras[0].fx);  // full precision, bit-exact
  EXPECT_EQ(back.cameras[0].cy, s.cameras[0].cy);
  EXPECT_EQ(back.cameras[0].source.params, s.cameras[0].source.params);
  EXPECT_EQ(back.cameras[0].source.model, "OPENCV");
  ASSERT_EQ(back.images.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(back.images[i].name, s.images[i].name);
    EXPECT_EQ(back.images[i].path, s.images[i].path);
    EXPECT_EQ(back.images[i].alpha_path, s.images[i].alpha_path);
    EXPECT_EQ(back.images[i].split, s.images[i].split);
    EXPECT_EQ(back.images[i].excluded_because, s.images[i].excluded_because);
    EXPECT_EQ(back.images[i].pose_doubt, s.images[i].pose_doubt);
    EXPECT_EQ(back.images[i].turn_group, s.images[i].turn_group);
    EXPECT_EQ(back.images[i].world_from_cam, s.images[i].world_from_cam);
    EXPECT_EQ(back.images[i].refined_world_from_cam, s.images[i].refined_world_from_cam);
    EXPECT_EQ(back.images[i].refined_focal_scale, s.images[i].refined_focal_scale);
  }
  EXPECT_TRUE(back.images[1].refined_focal_scale.has_value());
}

// The import's size limit: written, read back, and -1 (not recorded) in a scene.json of an
// older perf, which perf run then imports again rather than guess.
TEST(Scene, MaxSizeIsRecordedAndUnknownInOlderScenes) {
  Scene s = MakeScene();
  s.source.max_size = 400;
  EXPECT_EQ(SceneFromJson(SceneToJson(s), "scene.json").source.max_size, 400);
  nlohmann::json old = nlohmann::json::parse(SceneToJson(s));
  old["source"].erase("max_size");
  EXPECT_EQ(SceneFromJson(old.dump(), "scene.json").source.max_size, -1);
}

TEST(Scene, FileRoundTripAndMissingFile) {
  test::TempDir dir;
  WriteScene(dir / "scene.json", MakeScene());
  EXPECT_EQ(ReadScene(dir / "scene.json").images.size(), 3u);
  try {
    ReadScene(dir / "nope" / "scene.json");
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("perf import"), std::string::npos) << e.what();
  }
}

// Each corruption must give an InputError that names the field.
struct Corruption {
  const char* field;
  void (*apply)(nlohmann::json&);
};

class SceneCorruption : public ::testing::TestWithParam<Corruption> {};

TEST_P(SceneCorruption, NamesTheField) {
  nlohmann::json j = nlohmann::json::parse(SceneToJson(MakeScene()));
  GetParam().apply(j);
  try {
    SceneFromJson(j.dump(), "ws/scene.json");
    FAIL() << "expected InputError for " << GetParam().field;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("ws/scene.json"), std::string::npos) << msg;
    EXPECT_NE(msg.find(GetParam().field), std::string::npos) << msg;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Fields, SceneCorruption,
    ::testing::Values(
        Corruption{"version", [](nlohmann::json& j) { j["version"] = 99; }},
        Corruption{"format", [](nlohmann::json& j) { j["format"] = "other"; }},
        Corruption{"box.size", [](nlohmann::json& j) { j["box"]["size"][1] = -1.0; }},
        // Placements no export can hold (the checkpoint's own range): refused when read.
        Corruption{"box.center", [](nlohmann::json& j) { j["box"]["center"][0] = 1e300; }},
        Corruption{"box.size", [](nlohmann::json& j) { j["box"]["size"][2] = 1e300; }},
        Corruption{"shells.center", [](nlohmann::json& j) { j["shells"]["center"][1] = -1e300; }},
        Corruption{"shells.radii", [](nlohmann::json& j) { j["shells"]["radii"].back() = 1e300; }},
        Corruption{"box.rotation", [](nlohmann::json& j) { j["box"]["rotation"][0][0] = 2.0; }},
        Corruption{"shells.radii", [](nlohmann::json& j) { j["shells"]["radii"] = {3.0, 2.0}; }},
        Corruption{"cameras[0].fx", [](nlohmann::json& j) { j["cameras"][0]["fx"] = "abc"; }},
        Corruption{"cameras[0].width", [](nlohmann::json& j) { j["cameras"][0].erase("width"); }},
        Corruption{"images[1].camera_id", [](nlohmann::json& j) { j["images"][1]["camera_id"] = 3; }},
        Corruption{"images[2].split", [](nlohmann::json& j) { j["images"][2]["split"] = "val"; }},
        Corruption{"images[2].excluded_because", [](nlohmann::json& j) { j["images"][2]["excluded_because"] = 5; }},
        Corruption{"images[0].pose_doubt", [](nlohmann::json& j) { j["images"][0]["pose_doubt"] = true; }},
        Corruption{"images[0].turn_group", [](nlohmann::json& j) { j["images"][0]["turn_group"] = -3; }},
        Corruption{"images[0].turn_group", [](nlohmann::json& j) { j["images"][0]["turn_group"] = "one"; }},
        Corruption{"images[0].world_from_cam", [](nlohmann::json& j) { j["images"][0]["world_from_cam"][0][0] = 5.0; }},
        Corruption{"images", [](nlohmann::json& j) { j["images"] = nlohmann::json::array(); }},
        Corruption{"images[1].refined_focal_scale", [](nlohmann::json& j) { j["images"][1]["refined_focal_scale"] = 0.0; }},
        Corruption{"images[0].refined_focal_scale", [](nlohmann::json& j) { j["images"][0]["refined_focal_scale"] = "x"; }},
        // Paths that would read or write outside the workspace, and more shells than it solves.
        Corruption{"images[0].path", [](nlohmann::json& j) { j["images"][0]["path"] = "images/../../x.png"; }},
        Corruption{"images[1].path", [](nlohmann::json& j) { j["images"][1]["path"] = "/tmp/x.png"; }},
        Corruption{"images[0].alpha_path", [](nlohmann::json& j) { j["images"][0]["alpha_path"] = "../a.png"; }},
        Corruption{"shells.radii", [](nlohmann::json& j) { j["shells"]["radii"] = {1, 2, 3, 4, 5, 6, 7, 8, 9}; }}));

TEST(Scene, InvalidJsonIsInputError) {
  EXPECT_THROW(SceneFromJson("{ not json", "scene.json"), InputError);
  EXPECT_THROW(SceneFromJson("[1, 2]", "scene.json"), InputError);
  // A number beyond double (nlohmann's out_of_range, not a parse_error) names the file too.
  try {
    SceneFromJson(R"({"format": "perf-scene", "version": 1e400})", "ws/scene.json");
    FAIL() << "1e400 was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("ws/scene.json"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace perf
