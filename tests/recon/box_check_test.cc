// BoxFaces and CutOffWarning (box_check.h): density against a side face is named with its share,
// density on the bottom face (where the object stands) and inside the box is not, and a sparse
// grid's inactive cells are empty.
#include "recon_cuda/run/box_check.h"

#include <gtest/gtest.h>

namespace perf::recon {
namespace {

VolumeGeometry UnitBox() {
  VolumeGeometry g;
  g.box.size = {2.f, 2.f, 2.f};
  g.shell_radii = {3.f};
  return g;
}

TEST(BoxCheck, DensityAgainstASideFaceIsNamedTheBottomAndTheInsideAreNot) {
  const VolumeShape shape{8, 2, 1};
  std::vector<float> x(shape.ParamCount(), 0.f);
  const auto set_sigma = [&](int i, int j, int k, float s) { x[GridParam(GridCell(8, i, j, k), 3)] = s; };
  for (int i = 1; i < 7; ++i)
    for (int j = 1; j < 7; ++j) {
      set_sigma(i, j, 0, 50.f);                           // the floor, within the side faces
      for (int k = 2; k < 6; ++k) set_sigma(i, j, k, 50.f);  // the object, inside the box
    }
  set_sigma(0, 4, 3, 50.f);  // one cell of the object touches -x
  std::vector<BoxFace> faces = BoxFaces(shape, UnitBox(), x);
  ASSERT_EQ(faces.size(), 6u);
  EXPECT_EQ(faces[4].name, "-z (bottom)");
  EXPECT_DOUBLE_EQ(faces[4].opaque_fraction, 36.0 / 64);
  EXPECT_DOUBLE_EQ(faces[0].opaque_fraction, 1.0 / 64);  // -x
  for (int f : {1, 2, 3, 5}) EXPECT_DOUBLE_EQ(faces[f].opaque_fraction, 0.0) << faces[f].name;
  EXPECT_EQ(CutOffWarning(faces), "");  // the floor is not counted, one cell of -x is under 5 %

  // A quarter of the +x face, faintly: 1 - exp(-0.5 x 0.25) = 0.12 is not opaque; 20 per unit is.
  for (int j = 2; j < 6; ++j)
    for (int k = 3; k < 7; ++k) set_sigma(7, j, k, 0.5f);
  EXPECT_DOUBLE_EQ(BoxFaces(shape, UnitBox(), x)[1].opaque_fraction, 0.0);
  for (int j = 2; j < 6; ++j)
    for (int k = 3; k < 7; ++k) set_sigma(7, j, k, 20.f);
  faces = BoxFaces(shape, UnitBox(), x);
  EXPECT_DOUBLE_EQ(faces[1].opaque_fraction, 0.25);
  EXPECT_NE(CutOffWarning(faces).find("reaches the box's +x (25 % opaque) face:"), std::string::npos)
      << CutOffWarning(faces);
  for (int i = 2; i < 6; ++i)
    for (int k = 3; k < 5; ++k) set_sigma(i, 7, k, 20.f);  // and 8 cells of +y
  EXPECT_NE(CutOffWarning(BoxFaces(shape, UnitBox(), x)).find("+x (25 % opaque), +y (13 % opaque) faces:"),
            std::string::npos)
      << CutOffWarning(BoxFaces(shape, UnitBox(), x));

  // Nothing against a side or the top: no warning.
  std::vector<float> clear(shape.ParamCount(), 0.f);
  EXPECT_EQ(CutOffWarning(BoxFaces(shape, UnitBox(), clear)), "");
}

TEST(BoxCheck, TheFacesTheDensityReachesGrowOutwardInTheBoxFrame) {
  std::vector<BoxFace> faces(6);
  faces[0].opaque_fraction = 0.3;   // -x
  faces[3].opaque_fraction = 0.04;  // +y, under kCutOffFraction
  faces[4].opaque_fraction = 0.9;   // -z, the bottom: never grown
  faces[5].opaque_fraction = 0.05;  // +z, at the threshold
  EXPECT_EQ(FacesToGrow(faces), (std::vector<int>{0, 5}));

  VolumePlacement p;
  p.box_center[0] = 1, p.box_center[1] = 2, p.box_center[2] = 3;
  p.box_size[0] = 4, p.box_size[1] = 2, p.box_size[2] = 8;
  // world_from_box: box x along world y, box y along world -x, box z along world z.
  const double r[9] = {0, -1, 0, 1, 0, 0, 0, 0, 1};
  std::copy(r, r + 9, p.box_rotation);
  p.shell_radii = {10};
  const VolumePlacement g = GrownPlacement(p, {0, 5});
  EXPECT_DOUBLE_EQ(g.box_size[0], 4 + kGrowFraction * 4);
  EXPECT_DOUBLE_EQ(g.box_size[1], 2);
  EXPECT_DOUBLE_EQ(g.box_size[2], 8 + kGrowFraction * 8);
  // -x of the box is world -y: the centre moves half the step that way; +z moves it up.
  EXPECT_DOUBLE_EQ(g.box_center[0], 1);
  EXPECT_DOUBLE_EQ(g.box_center[1], 2 - 0.5 * kGrowFraction * 4);
  EXPECT_DOUBLE_EQ(g.box_center[2], 3 + 0.5 * kGrowFraction * 8);
  // The faces that did not grow stay where they were: box +x at centre + R e_x size / 2.
  EXPECT_DOUBLE_EQ(g.box_center[1] + 0.5 * g.box_size[0], p.box_center[1] + 0.5 * p.box_size[0]);
  EXPECT_DOUBLE_EQ(g.box_center[2] - 0.5 * g.box_size[2], p.box_center[2] - 0.5 * p.box_size[2]);
  // Both faces of an axis: the centre stays.
  const VolumePlacement both = GrownPlacement(p, {2, 3});
  EXPECT_DOUBLE_EQ(both.box_size[1], 2 + 2 * kGrowFraction * 2);
  for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(both.box_center[a], p.box_center[a]);
  EXPECT_EQ(g.shell_radii, p.shell_radii);

  // The default start (0.99 across the box): at 8^3 a fog cell can look opaque (0.68 at most in a
  // cube), at 16^3 (0.44) and 32^3 (0.25) it cannot.
  VolumeGeometry cube;
  cube.box.size = {2.f, 2.f, 2.f};
  cube.shell_radii = {3.f};
  EXPECT_TRUE(FogCanLookOpaque(0.99, cube, 8));
  EXPECT_FALSE(FogCanLookOpaque(0.99, cube, 16));
  EXPECT_FALSE(FogCanLookOpaque(0.99, cube, 32));
  cube.box.size = {1.f, 1.f, 4.f};  // a long box: its longest cells are 4 times the shortest
  EXPECT_TRUE(FogCanLookOpaque(0.99, cube, 16));
}

TEST(BoxCheck, InactiveBricksOfASparseGridAreEmpty) {
  std::vector<uint8_t> active(8, 0);
  active[1] = 1;  // the brick at +x, -y, -z of a 16^3 grid
  const VolumeShape shape = VolumeShape{16, 2, 1}.WithBricks(std::make_shared<const BrickGrid>(MakeBrickGrid(16, active)));
  std::vector<float> x(shape.ParamCount(), 0.f);
  for (int64_t c = 0; c < kBrickCells; ++c) x[GridParam(c, 3)] = 100.f;  // the stored brick is solid
  const std::vector<BoxFace> faces = BoxFaces(shape, UnitBox(), x);
  EXPECT_DOUBLE_EQ(faces[1].opaque_fraction, 0.25);  // +x: one brick of four
  EXPECT_DOUBLE_EQ(faces[0].opaque_fraction, 0.0);   // -x: inactive
  EXPECT_DOUBLE_EQ(faces[5].opaque_fraction, 0.0);   // +z
}

}  // namespace
}  // namespace perf::recon
