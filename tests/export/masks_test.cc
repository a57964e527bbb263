// Foreground masks, metrics, orbit cameras and the report's pieces, on volumes with known
// geometry: an opaque sphere in the box, whose silhouette from any camera is known exactly.
#include "export/masks.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <Eigen/Geometry>
#include <cmath>

#include "common/errors.h"
#include "export/metrics.h"
#include "export/orbit.h"
#include "export/report_html.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/data/training_data.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/undistort.h"
#include "tests/recon/recon_test_util.h"

namespace perf::exporter {
namespace {

using recon::VecId;

constexpr double kRadius = 0.7;
const Eigen::Vector3d kSphereCentre(0.15, -0.1, 0.05);

// An opaque sphere (sigma 60 / world unit: opacity 1 - e^-6 through a 0.1 chord) in a 2^3 box
// at the origin, clear shells. Cells whose centre is inside get the density, and trilinear
// interpolation spreads it over up to one more cell (0.016): the volume's own silhouette is up
// to that much wider than the true sphere's, 2 % of the radius here, which bounds the IoU the
// test can ask for at about 0.96.
struct SphereVolume {
  recon::VolumeShape shape{128, 4, 2};
  recon::VolumeGeometry geometry;
  std::vector<float> x;
  std::unique_ptr<recon::Backend> backend;
  recon::RaySet no_rays;

  SphereVolume() {
    geometry.box = {{0, 0, 0}, {{1, 0, 0, 0, 1, 0, 0, 0, 1}}, {2, 2, 2}};
    geometry.shell_center = {0, 0, 0};
    geometry.shell_radii = {3, 8};
    x.assign(shape.ParamCount(), 0.5f);
    const int n = shape.n;
    for (int k = 0; k < n; ++k) {
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
          const Eigen::Vector3d p(2 * (i + 0.5) / n - 1, 2 * (j + 0.5) / n - 1, 2 * (k + 0.5) / n - 1);
          x[recon::GridParam(recon::GridCell(n, i, j, k), 3)] = (p - kSphereCentre).norm() < kRadius ? 60.f : 0.f;
        }
      }
    }
    for (int64_t i = shape.GridParamCount(); i < shape.ParamCount(); i += 4) x[i + 3] = 0.f;  // clear inner shell
    backend = recon::MakeCpuBackend({});
    backend->SetLevel(recon::LevelProblem{shape, geometry, &no_rays, {}}, 1);
    backend->Upload(0, x);
  }
};

// A camera at distance 3.2 looking at the origin, as scene.json would hold it.
SceneImage ImageAt(double azimuth, double height) {
  const Eigen::Vector3d eye(3.2 * std::cos(azimuth), 3.2 * std::sin(azimuth), height);
  const Eigen::Vector3d z = (-eye).normalized();
  const Eigen::Vector3d xa = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(xa);
  SceneImage im;
  im.name = "view";
  im.world_from_cam << xa, y, z, eye;
  return im;
}

// Whether the ray through pinhole pixel (px, py) passes within the sphere.
bool RayHitsSphere(const SceneImage& im, double fx, double fy, double cx, double cy, double px, double py) {
  const Eigen::Vector3d d = (im.world_from_cam.leftCols<3>() * Eigen::Vector3d((px - cx) / fx, (py - cy) / fy, 1)).normalized();
  const Eigen::Vector3d o = im.world_from_cam.col(3);
  const Eigen::Vector3d to_centre = kSphereCentre - o;
  const double along = to_centre.dot(d);
  return (to_centre - along * d).norm() < kRadius;
}

TEST(Masks, PinholeMaskMatchesTheTrueSilhouette) {
  SphereVolume vol;
  SceneCamera cam;
  cam.width = 192;
  cam.height = 160;
  cam.fx = cam.fy = 220;
  cam.cx = 96;
  cam.cy = 80;
  cam.source = {"PINHOLE", {220, 220, 96, 80}, 192, 160};
  for (double az : {0.3, 1.9, 4.0}) {
    const SceneImage im = ImageAt(az, 0.7);
    const Image mask = Binarize(RenderWorkspaceMask(vol.backend.get(), 0, cam, im), 0.7);
    Image truth(cam.width, cam.height, 1);
    for (int j = 0; j < cam.height; ++j) {
      for (int i = 0; i < cam.width; ++i) truth.at(i, j, 0) = RayHitsSphere(im, cam.fx, cam.fy, cam.cx, cam.cy, i + 0.5, j + 0.5);
    }
    const MaskAgreement m = CompareMasks(mask, truth);
    EXPECT_GE(m.iou, 0.95) << "azimuth " << az << ": precision " << m.precision << ", recall " << m.recall;
    EXPECT_GT(m.truth, 2000) << "the sphere should fill a good part of the view";
    // The photo-frame path of a pinhole camera at the workspace size is the same mask.
    const PhotoFrame frame = PhotoFrame::Create(cam);
    const Image photo_mask = Binarize(RenderPhotoMask(vol.backend.get(), 0, cam, im, frame, {}), 0.7);
    EXPECT_EQ(photo_mask.pixels, mask.pixels);
  }
}

// An OPENCV camera with strong barrel distortion, imported at half size: the mask exported in
// the photo's own frame lines up with where the sphere projects in the distorted photo.
TEST(Masks, DistortedPhotoMaskLinesUpWithTheDistortedPhoto) {
  SphereVolume vol;
  colmap::Camera source;
  source.model_id = static_cast<int>(colmap::CameraModelId::kOpenCV);
  source.width = 320;
  source.height = 240;
  source.params = {260, 255, 161.5, 118.5, -0.28, 0.07, 0.002, -0.001};
  const Undistorter u = Undistorter::Create(source, "test camera");
  SceneCamera cam;
  cam.width = 160;
  cam.height = 120;
  cam.fx = u.pinhole().fx / 2;
  cam.fy = u.pinhole().fy / 2;
  cam.cx = u.pinhole().cx / 2;
  cam.cy = u.pinhole().cy / 2;
  cam.source = {"OPENCV", source.params, 320, 240};
  const SceneImage im = ImageAt(0.8, 0.4);
  const PhotoFrame frame = PhotoFrame::Create(cam);
  ASSERT_EQ(frame.width, 320);
  ASSERT_EQ(frame.height, 240);
  MaskOptions options;
  options.render_scale = 2;
  const Image soft = RenderPhotoMask(vol.backend.get(), 0, cam, im, frame, options);
  ASSERT_EQ(soft.width, 320);
  ASSERT_EQ(soft.height, 240);

  // Points just inside and just outside the silhouette, all around it, projected through
  // COLMAP's distorted model.
  const Eigen::Matrix3d r = im.world_from_cam.leftCols<3>();
  const Eigen::Vector3d eye = im.world_from_cam.col(3);
  const Eigen::Vector3d view = (kSphereCentre - eye).normalized();
  const Eigen::Vector3d a = view.cross(Eigen::Vector3d::UnitZ()).normalized(), b = view.cross(a);
  const auto project = [&](const Eigen::Vector3d& p, double* px, double* py) {
    const Eigen::Vector3d c = r.transpose() * (p - eye);
    colmap::ImgFromCam(colmap::CameraModelId::kOpenCV, source.params.data(), c.x(), c.y(), c.z(), px, py);
  };
  const auto mask_at = [&](double px, double py) { return soft.at(static_cast<int>(px), static_cast<int>(py), 0); };
  double px, py;
  project(kSphereCentre, &px, &py);
  EXPECT_GT(mask_at(px, py), 0.99f);
  int checked = 0;
  double naive_miss = 0;  // how far a plain resize of the pinhole mask would put the rim
  for (int k = 0; k < 24; ++k) {
    const double t = 2 * M_PI * k / 24;
    const Eigen::Vector3d dir = std::cos(t) * a + std::sin(t) * b;
    double ix, iy, ox, oy;
    project(kSphereCentre + 0.8 * kRadius * dir, &ix, &iy);
    project(kSphereCentre + 1.2 * kRadius * dir, &ox, &oy);
    if (ox < 1 || oy < 1 || ox > 319 || oy > 239) continue;
    EXPECT_GT(mask_at(ix, iy), 0.7f) << "inside the rim at angle " << t;
    EXPECT_LT(mask_at(ox, oy), 0.3f) << "outside the rim at angle " << t;
    double ux, uy;
    u.MapToDistorted(ox, oy, &ux, &uy);  // where a plain resize would read this pixel from
    naive_miss = std::max(naive_miss, std::hypot(ux - ox, uy - oy));
    ++checked;
  }
  EXPECT_GE(checked, 12);
  EXPECT_GT(naive_miss, 3.0) << "the distortion is too weak for this test to tell mapping from resizing";
}

TEST(Metrics, PsnrSsimAndMaskedScores) {
  Image a(32, 24, 3), b(32, 24, 3), mask(32, 24, 1);
  for (int j = 0; j < 24; ++j) {
    for (int i = 0; i < 32; ++i) {
      for (int c = 0; c < 3; ++c) a.at(i, j, c) = 0.2f + 0.6f * ((i * 7 + j * 3 + c * 5) % 11) / 10.f;
      mask.at(i, j, 0) = i < 16 ? 1.f : 0.f;
    }
  }
  ImageScores same = ScoreImage(a, a, mask);
  EXPECT_EQ(same.psnr, 99);
  EXPECT_NEAR(same.ssim, 1.0, 1e-6);
  EXPECT_NEAR(same.ssim_masked, 1.0, 1e-6);
  EXPECT_DOUBLE_EQ(same.mask_coverage, 0.5);
  // Error only outside the mask: the masked scores stay perfect, the whole-image ones drop.
  b = a;
  for (int j = 0; j < 24; ++j) {
    for (int i = 16; i < 32; ++i) b.at(i, j, 1) += (i + j) % 2 ? 0.1f : -0.1f;  // structure, not an offset
  }
  const ImageScores s = ScoreImage(b, a, mask);
  EXPECT_NEAR(s.psnr, 10 * std::log10(1 / (0.01 / 6)), 0.01);  // MSE: 0.01 on 1 of 6 values
  EXPECT_EQ(s.psnr_masked, 99);
  EXPECT_LT(s.ssim, 0.99);
  EXPECT_GT(s.ssim_masked, s.ssim);
}

TEST(Metrics, MaskAgreementCounts) {
  Image ours(4, 1, 1), truth(4, 1, 1);
  ours.pixels = {1, 1, 0, 0};
  truth.pixels = {0, 1, 1, 0};
  const MaskAgreement m = CompareMasks(ours, truth);
  EXPECT_EQ(m.both, 1);
  EXPECT_DOUBLE_EQ(m.iou, 1.0 / 3);
  EXPECT_DOUBLE_EQ(m.precision, 0.5);
  EXPECT_DOUBLE_EQ(m.recall, 0.5);
  MaskAgreement total;
  Accumulate(&total, m);
  Accumulate(&total, CompareMasks(truth, truth));
  EXPECT_DOUBLE_EQ(total.iou, 3.0 / 5);
}

TEST(Orbit, CamerasCircleTheBoxAndLookAtItsCentre) {
  Scene scene;
  scene.box.center = {1, 2, 3};
  scene.box.rotation = Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, -0.2, 1).normalized()).toRotationMatrix();
  scene.cameras.push_back(SceneCamera{1, 64, 48, 50, 50, 32, 24, {}});
  for (double d : {4.0, 5.0, 6.0}) {
    SceneImage im = ImageAt(d, 0);
    im.camera_id = 1;
    im.world_from_cam.col(3) = scene.box.center + Eigen::Vector3d(d, 0, 0);
    scene.images.push_back(im);
  }
  OrbitOptions o;
  o.frames = 8;
  o.elevation_degrees = 30;
  const std::vector<OrbitView> views = OrbitCameras(scene, o);
  ASSERT_EQ(views.size(), 8u);
  const Eigen::Vector3d up = scene.box.rotation.col(2);
  for (const OrbitView& v : views) {
    EXPECT_EQ(v.width, 64);
    Eigen::Matrix<double, 3, 4> m;
    for (int i = 0; i < 12; ++i) m(i / 4, i % 4) = v.camera.world_from_cam[i];
    const Eigen::Vector3d to_centre = scene.box.center - m.col(3);
    EXPECT_NEAR(to_centre.norm(), 5.0, 1e-5);  // the median camera distance
    // The centre projects to the image centre, and the box's up points up in the image.
    const Eigen::Vector3d c = m.leftCols<3>().transpose() * to_centre;
    EXPECT_NEAR(v.camera.fx * c.x() / c.z() + v.camera.cx, 32, 1e-3);
    EXPECT_NEAR(v.camera.fy * c.y() / c.z() + v.camera.cy, 24, 1e-3);
    EXPECT_LT((m.leftCols<3>().transpose() * up).y(), 0);
    EXPECT_NEAR(std::asin(-to_centre.normalized().dot(up)), 30 * M_PI / 180, 1e-5);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(m.col(i).norm(), 1.0, 1e-5);
    EXPECT_NEAR(m.col(0).cross(m.col(1)).dot(m.col(2)), 1.0, 1e-5);  // right-handed
  }
  o.frames = 0;
  EXPECT_THROW(OrbitCameras(scene, o), InputError);
}

// A frontal capture's orbit sweeps the arc its photos see from (and back); a capture all round
// gets a full turn; the photos left out do not count.
TEST(Orbit, FollowsTheArcThePhotosCover) {
  Scene scene;
  scene.box.center = {1, 2, 3};
  scene.box.rotation = Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, -0.2, 1).normalized()).toRotationMatrix();
  scene.cameras.push_back(SceneCamera{1, 64, 48, 50, 50, 32, 24, {}});
  const auto add = [&](double degrees, Split split) {
    SceneImage im = ImageAt(5, 0);
    im.camera_id = 1;
    im.split = split;
    const double a = degrees * M_PI / 180;
    im.world_from_cam.col(3) = scene.box.center + scene.box.rotation * Eigen::Vector3d(5 * std::cos(a), 5 * std::sin(a), 1);
    scene.images.push_back(im);
  };
  for (double d = 10; d <= 100; d += 15) add(d, Split::kTrain);
  add(250, Split::kExcluded);  // a wrong pose on the far side
  const Arc arc = CapturedArc(scene);
  EXPECT_NEAR(arc.start, 10 * M_PI / 180, 1e-9);
  EXPECT_NEAR(arc.span, 90 * M_PI / 180, 1e-9);
  OrbitOptions o;
  o.frames = 20;
  double lowest = 10, highest = -10;
  for (const OrbitView& v : OrbitCameras(scene, o)) {
    Eigen::Vector3d eye;
    for (int i = 0; i < 3; ++i) eye[i] = v.camera.world_from_cam[4 * i + 3];
    const Eigen::Vector3d d = scene.box.rotation.transpose() * (eye - scene.box.center);
    const double a = std::atan2(d.y(), d.x());
    lowest = std::min(lowest, a);
    highest = std::max(highest, a);
  }
  EXPECT_NEAR(lowest, 10 * M_PI / 180, 1e-4);
  EXPECT_NEAR(highest, 100 * M_PI / 180, 1e-4);
  o.follow_capture = false;
  double full_lowest = 10;
  for (const OrbitView& v : OrbitCameras(scene, o)) {
    const Eigen::Vector3d eye(v.camera.world_from_cam[3], v.camera.world_from_cam[7], v.camera.world_from_cam[11]);
    const Eigen::Vector3d d = scene.box.rotation.transpose() * (eye - scene.box.center);
    full_lowest = std::min(full_lowest, std::atan2(d.y(), d.x()));
  }
  EXPECT_LT(full_lowest, -2.5) << "without following, a full turn";

  // Photos all round: a full turn. One direction alone: the narrowest arc, centred on it.
  for (double d = 130; d < 360; d += 30) add(d, Split::kTest);
  EXPECT_NEAR(CapturedArc(scene).span, 2 * M_PI, 1e-12);
  Scene one = scene;
  one.images.resize(1);
  EXPECT_NEAR(CapturedArc(one).span, kMinOrbitArc, 1e-12);
  EXPECT_NEAR(CapturedArc(one).start + kMinOrbitArc / 2, 10 * M_PI / 180, 1e-9);
}

TEST(Report, Base64AndPlot) {
  EXPECT_EQ(Base64({'M', 'a', 'n'}), "TWFu");
  EXPECT_EQ(Base64({'M', 'a'}), "TWE=");
  EXPECT_EQ(Base64({'M'}), "TQ==");
  EXPECT_EQ(Base64({}), "");
  EXPECT_EQ(PsnrPlotSvg(""), "");
  const std::string log =
      "{\"event\":\"iteration\",\"level\":0,\"elapsed\":1.0,\"train_psnr\":15.0}\n"
      "{\"event\":\"iteration\",\"level\":1,\"elapsed\":2.0,\"train_psnr\":20.0,\"test_psnr\":19.5}\n"
      "not json\n";
  const std::string svg = PsnrPlotSvg(log);
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("<polyline"), std::string::npos);
  EXPECT_NE(svg.find("<circle"), std::string::npos);        // the held-out point
  EXPECT_NE(svg.find("stroke-dasharray"), std::string::npos);  // the level boundary
  EXPECT_NE(svg.find("held-out views"), std::string::npos);
  // No held-out PSNR logged (a level without held-out views logs 0): no point, no legend entry.
  const std::string train_only = PsnrPlotSvg(
      "{\"event\":\"iteration\",\"level\":0,\"elapsed\":1.0,\"train_psnr\":15.0}\n"
      "{\"event\":\"level\",\"level\":0,\"elapsed\":1.5,\"train_psnr\":16.0,\"test_psnr\":0}\n");
  EXPECT_NE(train_only.find("training rays"), std::string::npos);
  EXPECT_EQ(train_only.find("held-out views"), std::string::npos);
  EXPECT_EQ(train_only.find("<circle"), std::string::npos);
}

// A held-out view whose mask is empty has no PSNR inside its mask: the table says so instead of 0.
TEST(Report, AViewWithoutAMaskSaysSo) {
  const nlohmann::json scores = {{"psnr", 21.5}, {"ssim", 0.5}, {"psnr_masked", 23.25}, {"ssim_masked", 0.6},
                                 {"mask_coverage", 0.3}};
  nlohmann::json empty = {{"psnr", 12.45}, {"ssim", 0.2}, {"psnr_masked", 0.0}, {"ssim_masked", 0.0},
                          {"mask_coverage", 0.0}};
  nlohmann::json with_mask = scores;
  with_mask["name"] = "a.png";
  empty["name"] = "b.png";
  const nlohmann::json report = {{"mean", scores}, {"test_views", {with_mask, empty}}};
  const std::string html = ReportHtml(report, {}, "");
  const size_t a = html.find("<td>a.png</td>"), b = html.find("<td>b.png</td>");
  ASSERT_NE(a, std::string::npos);
  ASSERT_NE(b, std::string::npos);
  const std::string row_a = html.substr(a, html.find("</tr>", a) - a), row_b = html.substr(b, html.find("</tr>", b) - b);
  EXPECT_NE(row_a.find("23.25"), std::string::npos) << row_a;
  EXPECT_EQ(row_a.find("no mask"), std::string::npos) << row_a;
  EXPECT_NE(row_b.find("no mask"), std::string::npos) << row_b;
  EXPECT_EQ(row_b.find("0.00"), std::string::npos) << row_b;
  EXPECT_EQ(html.find("in doubt"), std::string::npos);
  // A view whose imported pose is in doubt (scene.json pose_doubt) is marked, and the reason listed.
  nlohmann::json doubted = report;
  doubted["test_views"][1]["pose_doubt"] = "in a group that sees the object elsewhere";
  const std::string marked = ReportHtml(doubted, {}, "");
  EXPECT_NE(marked.find("<td>b.png *</td>"), std::string::npos) << marked;
  EXPECT_NE(marked.find("<td>a.png</td>"), std::string::npos) << marked;
  EXPECT_NE(marked.find("<li>b.png: in a group that sees the object elsewhere</li>"), std::string::npos) << marked;
}

}  // namespace
// report.html plots the cameras (one marker per photo by split, a refined camera's move), shows
// each held-out view's mask beside its render and photo, and links report.json instead of
// dumping it.
TEST(Report, PlotsTheCamerasShowsMasksAndLinksTheJson) {
  Scene scene;
  scene.box.size = {2, 2, 1};
  const auto add = [&](const char* name, Split split, double angle, bool refined) {
    SceneImage im;
    im.name = name;
    im.split = split;
    const Eigen::Vector3d c(4 * std::cos(angle), 4 * std::sin(angle), 0.5);
    im.world_from_cam.col(3) = c;
    im.world_from_cam.col(2) = -c.normalized();  // looking at the box
    if (refined) {
      im.refined_world_from_cam = im.world_from_cam;
      im.refined_world_from_cam->col(3) += Eigen::Vector3d(0.2, 0, 0);
    }
    scene.images.push_back(im);
  };
  add("a.png", Split::kTrain, 0.0, true);
  add("b.png", Split::kTrain, 1.0, false);
  add("c.png", Split::kTest, 2.0, false);
  add("d.png", Split::kExcluded, 3.0, false);
  const std::string svg = CamerasPlotSvg(scene);
  const auto count = [](const std::string& text, const std::string& what) {
    size_t n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count(svg, "<g class=\"cam train\">"), 2u);
  EXPECT_EQ(count(svg, "<g class=\"cam test\">"), 1u);
  EXPECT_EQ(count(svg, "<g class=\"cam excluded\">"), 1u);
  EXPECT_EQ(count(svg, "class=\"refined\""), 1u);
  EXPECT_EQ(count(svg, "<rect"), 1u);

  const nlohmann::json scores = {{"psnr", 21.5}, {"ssim", 0.5}, {"psnr_masked", 23.25}, {"ssim_masked", 0.6},
                                 {"mask_coverage", 0.3}};
  nlohmann::json view = scores;
  view["name"] = "c.png";
  const nlohmann::json report = {{"mean", scores}, {"test_views", {view}}};
  ReportStripView strip{"c.png", Image(8, 6, 3), Image(8, 6, 3), Image(8, 6, 1), {}};
  strip.mask.pixels[5] = 1.f;
  const std::string html = ReportHtml(report, {strip}, "", &scene);
  EXPECT_NE(html.find("id=\"cameras-plot\""), std::string::npos);
  EXPECT_NE(html.find("alt=\"mask\""), std::string::npos);
  EXPECT_NE(html.find("href=\"report.json\""), std::string::npos);
  EXPECT_EQ(html.find("<pre>"), std::string::npos);  // no raw dump
  EXPECT_EQ(ReportHtml(report, {}, "").find("cameras-plot"), std::string::npos);  // no scene: no plot
}

}  // namespace perf::exporter
