#include "export/evaluate.h"

#include <Eigen/Core>
#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/stopwatch.h"
#include "export/export.h"
#include "export/masks.h"
#include "export/report_html.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/pose_fit.h"
#include "recon_cuda/run/refined_poses.h"
#include "recon_cuda/run/render_views.h"
#include "workspace/image_io.h"

namespace perf::exporter {

namespace fs = std::filesystem;
using recon::LoadedCheckpoint;

namespace {

// How many held-out views the HTML report shows next to their photos.
constexpr int kStripViews = 6;

void Progress(const EvalOptions& o, const std::string& step, int done, int total) {
  if (o.progress) o.progress(step, done, total);
}

// DIR/<name>.<ext> (the photo's name without extension) or DIR/<photo file name>.png (COLMAP's
// mask convention); empty if neither exists.
fs::path FindTrueMask(const fs::path& dir, const SceneImage& im) {
  const fs::path name = OutputName(im);
  for (const char* ext : {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".bmp"}) {
    const fs::path p = dir / fs::path(name).concat(ext);
    if (fs::exists(p)) return p;
  }
  const fs::path colmap_style = dir / fs::path(im.name).concat(".png");
  return fs::exists(colmap_style) ? colmap_style : fs::path();
}

void CompareWithTruth(const EvalOptions& o, const Scene& scene, LoadedCheckpoint& l, EvalResult* r) {
  const bool from_dir = !o.gt_masks.empty();
  if (from_dir && !fs::is_directory(o.gt_masks)) {
    throw IoError(o.gt_masks.string(), "is not a folder", "pass the folder that holds one mask image per photo");
  }
  std::map<int, PhotoFrame> frames;
  // Each image with a true mask, and that mask's file.
  std::vector<std::pair<const SceneImage*, fs::path>> with_truth;
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) continue;  // a wrong pose: our mask of it is not scored
    const fs::path file = from_dir ? FindTrueMask(o.gt_masks, im)
                                   : (im.alpha_path.empty() ? fs::path() : o.workspace / im.alpha_path);
    if (!file.empty()) with_truth.emplace_back(&im, file);
  }
  if (from_dir && with_truth.empty()) {
    throw InputError(o.gt_masks.string(), "mask files", "none found",
                     StrCat("expected one image per photo named like the photo, e.g. ",
                            (o.gt_masks / OutputName(scene.images.front())).string(), ".png"),
                     "check the folder and the names");
  }
  if (with_truth.empty()) return;
  r->mask_truth = from_dir ? "gt-masks" : "alpha";
  double iou_sum = 0;
  int done = 0;
  for (const auto& [im, file] : with_truth) {
    const SceneCamera& cam = scene.camera(im->camera_id);
    const Image truth = MaskChannel(ReadImage(file));
    Image ours;
    if (from_dir) {
      if (truth.width != cam.source.width || truth.height != cam.source.height) {
        throw InputError(file.string(), "size", StrCat(truth.width, "x", truth.height),
                         StrCat("the photo '", im->name, "' is ", cam.source.width, "x", cam.source.height),
                         "masks must have the photos' size");
      }
      auto it = frames.find(cam.id);
      if (it == frames.end()) it = frames.emplace(cam.id, PhotoFrame::Create(cam)).first;
      ours = RenderPhotoMask(l.backend.get(), LoadedCheckpoint::kParams, cam, *im, it->second, {});
    } else {
      if (truth.width != cam.width || truth.height != cam.height) {
        throw InputError(file.string(), "size", StrCat(truth.width, "x", truth.height),
                         StrCat("the workspace image is ", cam.width, "x", cam.height),
                         "the workspace changed after import; re-run perf import");
      }
      ours = RenderWorkspaceMask(l.backend.get(), LoadedCheckpoint::kParams, cam, *im);
    }
    const MaskAgreement m = CompareMasks(Binarize(ours, o.mask_threshold), Binarize(truth, 0.5));
    r->masks.push_back({im->name, SplitName(im->split), m});
    Accumulate(&r->pooled, m);
    iou_sum += m.iou;
    Progress(o, "masks", ++done, static_cast<int>(with_truth.size()));
  }
  r->mean_iou = iou_sum / with_truth.size();
}

nlohmann::json ScoresJson(const ImageScores& s) {
  return {{"psnr", s.psnr},
          {"ssim", s.ssim},
          {"psnr_masked", s.psnr_masked},
          {"ssim_masked", s.ssim_masked},
          {"mask_coverage", s.mask_coverage}};
}

nlohmann::json AgreementJson(const MaskAgreement& m) {
  return {{"iou", m.iou}, {"precision", m.precision}, {"recall", m.recall}};
}

// The second score of each held-out view (EvalResult::pose_fit): its camera fitted alone to its
// photo against the frozen volume, from the camera its neighbours' corrections give it.
void ScoreAfterPoseFit(const EvalOptions& o, LoadedCheckpoint& l, const std::vector<recon::PosedImage>& test,
                       const recon::PhotoCorrections& corrections, EvalResult* r) {
  Progress(o, "pose fit", 0, 1);
  const auto t0 = WallClock::now();
  const recon::Checkpoint& c = l.checkpoint;
  const recon::VolumeGeometry geometry = recon::GeometryOf(c);
  std::vector<recon::ColourTransform<float>> transforms;
  std::vector<recon::PoseValues> start;
  std::vector<recon::PosedImage> small;  // the photos the fit sees (EvalOptions::pose_fit_side)
  for (const recon::PosedImage& v : test) {
    transforms.push_back(corrections.TransformFor(v.camera));
    start.push_back(corrections.PoseFor(v.camera));
    const int factor = PoseFitDownscale(v.image.width, v.image.height, o.pose_fit_side);
    small.push_back(factor > 1 ? recon::Downscaled(v, factor) : v);
  }
  recon::PoseFitOptions fit;
  fit.iterations = o.pose_fit_iterations;
  // Its own backend: the loaded one keeps the render-only level the renders below use.
  const std::unique_ptr<recon::Backend> fit_backend = recon::MakeBackend(o.device, o.threads);
  const std::vector<recon::PoseValues> fitted =
      recon::FitViewPoses(fit_backend.get(), c.shape, c.params, geometry, small, transforms, start, fit);
  double sum = 0;
  for (size_t k = 0; k < test.size(); ++k) {
    recon::PosedImage moved = test[k];
    moved.camera = recon::CorrectedCamera(test[k].camera, fitted[k].data(), geometry);
    recon::RenderOutput render = l.backend->Render(LoadedCheckpoint::kParams, moved.camera, moved.image.width,
                                                   moved.image.height, o.min_box_opacity);
    recon::ApplyTransform(transforms[k], &render);
    ViewReport& v = r->views[k];
    v.psnr_pose_fit = recon::Psnr(render, moved.image);
    const Eigen::Vector3d box(c.placement.box_center[0], c.placement.box_center[1], c.placement.box_center[2]);
    const recon::CameraMove m = recon::MoveBetween(recon::WorldFromCam(corrections.CameraFor(test[k].camera)),
                                                   recon::WorldFromCam(moved.camera), box);
    v.pose_fit_degrees = m.degrees;
    v.pose_fit_centre_fraction = m.centre_fraction;
    sum += v.psnr_pose_fit;
  }
  r->pose_fit = true;
  r->mean_psnr_pose_fit = sum / static_cast<double>(test.size());
  r->pose_fit_seconds = SecondsSince(t0);
  Progress(o, "pose fit", 1, 1);
}

nlohmann::json ReportJson(const EvalOptions& o, const EvalResult& r, const LoadedCheckpoint& l) {
  nlohmann::json j;
  j["format"] = "perf-report";
  j["version"] = 1;
  j["checkpoint"] = fs::relative(r.checkpoint, o.workspace).generic_string();
  j["grid"] = {{"n", l.checkpoint.shape.n}, {"m", l.checkpoint.shape.m}, {"shells", l.checkpoint.shape.num_shells}};
  j["settings"] = {{"mask_threshold", o.mask_threshold},
                   {"min_box_opacity", o.min_box_opacity},
                   {"ssim", "OpenCV quality::QualitySSIM (Gaussian 11x11, sigma 1.5), mean over RGB"},
                   {"masked", "over the pixels inside our binary mask of the view"}};
  nlohmann::json views = nlohmann::json::array();
  for (const ViewReport& v : r.views) {
    nlohmann::json e = ScoresJson(v.scores);
    e["name"] = v.name;
    if (!v.pose_doubt.empty()) e["pose_doubt"] = v.pose_doubt;
    if (r.pose_fit) {
      e["psnr_pose_fit"] = v.psnr_pose_fit;
      e["pose_fit_moved"] = {{"degrees", v.pose_fit_degrees}, {"centre_fraction", v.pose_fit_centre_fraction}};
    }
    views.push_back(e);
  }
  j["test_views"] = views;
  j["mean"] = ScoresJson(r.mean);
  const bool refined = l.checkpoint.shape.poses > 0;
  j["held_out_cameras"] = {
      {"headline", refined ? "each view's camera moved by the inverse-distance blend of its two nearest training "
                             "photos' refined corrections (the photo being scored is not used)"
                           : "as imported"},
      {"pose_fit", r.pose_fit ? nlohmann::json{{"mean_psnr", r.mean_psnr_pose_fit},
                                               {"protocol", StrCat("each view's camera fitted alone to its photo "
                                                                   "against the frozen volume (Gauss-Newton, ",
                                                                   o.pose_fit_iterations, " iterations",
                                                                   o.pose_fit_side > 0
                                                                       ? StrCat(", the photo at most ", o.pose_fit_side,
                                                                                " px across")
                                                                       : std::string(),
                                                                   "), then scored; uses the photo being "
                                                                   "scored, so it is not the headline")},
                                               {"seconds", r.pose_fit_seconds}}
                              : nlohmann::json(nullptr)}};
  if (!r.mask_truth.empty()) {
    nlohmann::json per = nlohmann::json::array();
    for (const MaskReport& m : r.masks) {
      nlohmann::json e = AgreementJson(m.agreement);
      e["name"] = m.name;
      e["split"] = m.split;
      per.push_back(e);
    }
    j["masks"] = {{"truth", r.mask_truth},
                  {"images", r.masks.size()},
                  {"pooled", AgreementJson(r.pooled)},
                  {"mean_iou", r.mean_iou},
                  {"per_image", per}};
  }
  const fs::path recon_json = o.workspace / "recon" / "recon.json";
  if (fs::exists(recon_json)) {
    try {
      const nlohmann::json rj = nlohmann::json::parse(ReadFileToString(recon_json));
      j["reconstruction"] = {{"solver", rj.value("solver", "")},
                             {"backend", rj.value("backend", "")},
                             {"levels", rj.value("levels", 0)},
                             {"solve_seconds", rj.value("solve_seconds", 0.0)}};
    } catch (const nlohmann::json::exception&) {
      // recon.json is a summary for people; a damaged one leaves its fields out of the report.
    }
  }
  return j;
}

}  // namespace

EvalResult RunEval(const EvalOptions& o) {
  if (!(o.mask_threshold > 0 && o.mask_threshold <= 1)) {
    throw InputError("command line", "--mask-threshold", StrCat(o.mask_threshold), "must be in (0, 1]");
  }
  const Scene scene = ReadScene(o.workspace / "scene.json");
  LoadedCheckpoint l = recon::LoadForRendering(o.workspace, o.checkpoint, o.device, o.threads);
  EnsureWritableDirectory(o.workspace);
  EvalResult r;
  r.checkpoint = l.path;

  const std::vector<recon::PosedImage> test = recon::LoadImages(scene, o.workspace, Split::kTest);
  // Each held-out render under the blend of its two nearest training photos' exposures (recon/exposure.h).
  const recon::PhotoCorrections exposures = recon::CorrectionsOf(l, scene);
  std::vector<ReportStripView> strip;
  int masked_views = 0;
  for (const recon::PosedImage& v : test) {
    const recon::RenderOutput render =
        recon::RenderAsShot(l.backend.get(), LoadedCheckpoint::kParams, v, o.min_box_opacity, exposures);
    const Image image = recon::ToImage(render);
    Image mask = Binarize(recon::OpacityImage(render), o.mask_threshold);
    const ImageScores s = ScoreImage(image, v.image, mask);
    ViewReport& view = r.views.emplace_back();
    view.name = v.name;
    view.scores = s;
    for (const SceneImage& im : scene.images) {
      if (im.name == v.name) view.pose_doubt = im.pose_doubt;
    }
    r.mean.psnr += s.psnr;
    r.mean.ssim += s.ssim;
    r.mean.mask_coverage += s.mask_coverage;
    if (s.mask_coverage > 0) {
      r.mean.psnr_masked += s.psnr_masked;
      r.mean.ssim_masked += s.ssim_masked;
      ++masked_views;
    }
    if (static_cast<int>(strip.size()) < kStripViews) strip.push_back({v.name, v.image, image, std::move(mask), s});
    Progress(o, "views", static_cast<int>(r.views.size()), static_cast<int>(test.size()));
  }
  if (!r.views.empty()) {
    const double n = static_cast<double>(r.views.size());
    r.mean.psnr /= n;
    r.mean.ssim /= n;
    r.mean.mask_coverage /= n;
  }
  if (masked_views > 0) {
    r.mean.psnr_masked /= masked_views;
    r.mean.ssim_masked /= masked_views;
  }
  if (l.checkpoint.shape.poses > 0 && !test.empty()) ScoreAfterPoseFit(o, l, test, exposures, &r);
  CompareWithTruth(o, recon::PosedAsCheckpoint(l, scene), l, &r);

  const nlohmann::json report = ReportJson(o, r, l);
  WriteFileAtomically(o.workspace / "report.json", report.dump(2) + "\n");
  if (o.html) {
    const fs::path log = o.workspace / "recon" / "log.jsonl";
    const std::string log_text = fs::exists(log) ? ReadFileToString(log) : std::string();
    const Scene cameras = recon::WithRefinedPoses(scene, exposures);  // imported, and refined where solved
    WriteFileAtomically(o.workspace / "report.html", ReportHtml(report, strip, log_text, &cameras));
  }
  return r;
}

}  // namespace perf::exporter
