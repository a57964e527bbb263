#include "recon_cuda/run/turn_search.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <set>

#include "common/errors.h"
#include "common/stopwatch.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/run/evaluation.h"
#include "recon_cuda/run/photo_corrections.h"
#include "recon_cuda/run/pose_fit.h"
#include "recon_cuda/run/reconstruct_run.h"
#include "recon_cuda/solve/hierarchy.h"

namespace perf::recon {
namespace {

using Pose = Eigen::Matrix<double, 3, 4>;

Eigen::Matrix3d AxisTurn(const Eigen::Vector3d& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * std::numbers::pi / 180, axis.normalized()).toRotationMatrix();
}

double Degrees(const Eigen::Matrix3d& turn) { return Eigen::AngleAxisd(turn).angle() * 180 / std::numbers::pi; }

std::string Db(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f dB", v);
  return buf;
}

// A group's training photos, downscaled for scoring, and their poses as imported.
struct GroupViews {
  std::vector<PosedImage> views;
  std::vector<Pose> poses;
};

void SetPose(const Pose& p, PinholeCamera<float>* camera) {
  for (int k = 0; k < 12; ++k) camera->world_from_cam[k] = static_cast<float>(p(k / 4, k % 4));
}

// The colour transform (a gain and an offset per channel, by least squares) that takes `render`
// closest to `photo`: the group's exposures are not known to the volume of the other photos.
ColourTransform<float> BestTransform(const RenderOutput& render, const Image& photo) {
  ColourTransform<float> xf;
  const size_t n = static_cast<size_t>(render.width) * render.height;
  for (int c = 0; c < 3; ++c) {
    double sr = 0, sp = 0, srr = 0, srp = 0;
    for (size_t i = 0; i < n; ++i) {
      const double r = render.colour[3 * i + c], p = photo.pixels[photo.channels * i + c];
      sr += r, sp += p, srr += r * r, srp += r * p;
    }
    const double var = srr - sr * sr / n, cov = srp - sr * sp / n;
    const double gain = var > 1e-12 ? std::clamp(cov / var, 0.2, 5.0) : 1.0;
    xf.gain[c] = static_cast<float>(gain);
    xf.offset[c] = static_cast<float>((sp - gain * sr) / n);
  }
  return xf;
}

// Each view rendered and scored after its best colour transform (BestTransform).
std::vector<ViewScore> ScoreExposed(Backend* backend, VecId x, const std::vector<PosedImage>& views,
                                    std::vector<ColourTransform<float>>* transforms = nullptr) {
  std::vector<ViewScore> scores;
  for (const PosedImage& v : views) {
    RenderOutput render = RenderAsShot(backend, x, v, 0.f);
    const ColourTransform<float> xf = BestTransform(render, v.image);
    ApplyTransform(xf, &render);
    scores.push_back({v.name, Psnr(render, v.image)});
    if (transforms != nullptr) transforms->push_back(xf);
  }
  return scores;
}

// The views' mean PSNR with every pose moved by `move`.
double ScoreMove(Backend* backend, VecId x, GroupViews& g, const GroupMove& move) {
  for (size_t i = 0; i < g.views.size(); ++i) SetPose(move.Apply(g.poses[i]), &g.views[i].camera);
  return MeanPsnr(ScoreExposed(backend, x, g.views));
}

// The cameras' mean up direction (COLMAP's camera y points down the image).
Eigen::Vector3d MeanUp(const Scene& scene, const std::set<std::string>& marked) {
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kTrain && !marked.count(im.name)) up -= im.world_from_cam.col(1);
  }
  return up.norm() > 1e-9 ? up.normalized() : Eigen::Vector3d::UnitZ();
}

// What the hierarchy fits the search's volume from: the training photos outside every group.
struct Others {
  std::vector<PosedImage> photos;
  std::vector<ViewFrustum> views;
};

Others OtherPhotos(const ReconstructRun& run, const std::set<std::string>& marked) {
  Others o;
  for (const PosedImage& p : run.train) {
    if (marked.count(p.name)) continue;
    o.photos.push_back(p);
    o.views.push_back({p.camera, p.image.width, p.image.height});
  }
  return o;
}

class Searcher {
 public:
  // marked: the photos of every group (the up axis is the other training cameras').
  Searcher(ReconstructRun& run, const TurnSearchOptions& o, const std::set<std::string>& marked)
      : run_(run), o_(o), marked_(marked) {}

  // The backend holds the level fitted from the other photos: x its parameters there, `level` and
  // `params` the same on the host (for the pose fit's own backend).
  TurnSearch Search(Backend* backend, VecId x, const VolumeShape& level, const std::vector<float>& params, int group,
                    const std::vector<std::string>& photos) {
    TurnSearch t;
    t.group = group;
    t.photos = photos;
    GroupViews g = Views(photos, o_.max_pixels);
    t.scored = static_cast<int>(g.views.size());
    if (g.views.empty()) {
      t.why = "none of its photos is a training photo: nothing to score a move by; the poses stay as imported";
      return t;
    }
    const Eigen::Vector3d pivot = run_.scene.box.center, up = MeanUp(run_.scene, marked_);
    Eigen::Vector3d toward = Eigen::Vector3d::Zero();
    for (const Pose& p : g.poses) toward += p.col(3) - pivot;
    const auto score = [&](const GroupMove& m) { return ScoreMove(backend, x, g, m); };
    const auto start = WallClock::now();
    t.psnr_before = score(GroupMove{});
    const auto turn_score = [&](const Eigen::Matrix3d& turn) { return score(GroupMove::Turn(pivot, turn)); };
    const GroupMove turned = GroupMove::Turn(pivot, FindTurn(turn_score, up, toward, o_, &t.turns_tried));
    t.turn_degrees = turned.Degrees();
    t.psnr_turned = score(turned);
    t.turn_seconds = SecondsSince(start);
    const std::vector<Pose> fitted = FitEach(backend, x, turned, level, params, photos);
    GroupViews f = g;
    for (size_t i = 0; i < f.views.size(); ++i) f.poses[i] = fitted[i];
    t.psnr_fitted = ScoreMove(backend, x, f, GroupMove{});
    const GroupMove similarity = GroupMove::Between(g.poses, fitted);
    t.psnr_moved = score(similarity);
    t.fit_seconds = SecondsSince(start) - t.turn_seconds;
    const bool by_similarity = t.psnr_moved > t.psnr_turned;
    t.chosen = by_similarity ? "similarity" : "turn";
    const double best = std::max(t.psnr_moved, t.psnr_turned);
    t.used = best >= t.psnr_before + o_.min_gain_db;
    if (t.used) t.move = by_similarity ? similarity : turned;
    t.why = StrCat("its ", t.scored, " training photos fit ", Db(t.psnr_before), " as imported, ", Db(t.psnr_turned),
                   " turned ", static_cast<int>(std::lround(t.turn_degrees)), " degrees about the box centre (",
                   t.turns_tried, " turns tried), ", Db(t.psnr_fitted), " with each camera fitted alone and ",
                   Db(t.psnr_moved), " moved by the similarity of those fits (",
                   static_cast<int>(std::lround(similarity.Degrees())), " degrees, scale ",
                   std::lround(similarity.scale * 100) / 100.0, "): ",
                   t.used ? StrCat("the ", t.chosen, " is used") : StrCat("none is used (less than ", o_.min_gain_db,
                                                                          " dB better)"));
    return t;
  }

 private:
  GroupViews Views(const std::vector<std::string>& photos, int max_pixels) const {
    GroupViews g;
    const std::set<std::string> names(photos.begin(), photos.end());
    for (const PosedImage& p : run_.train) {
      if (!names.count(p.name)) continue;
      const int across = std::max(p.image.width, p.image.height);
      const int factor = std::max(1, (across + max_pixels - 1) / max_pixels);
      g.views.push_back(factor > 1 ? Downscaled(p, factor) : p);
      for (const SceneImage& im : run_.scene.images) {
        if (im.name == p.name) g.poses.push_back(im.world_from_cam);
      }
    }
    return g;
  }

  // Each of the group's training cameras fitted alone to its photo (pose_fit.h, on a backend of
  // its own: `backend` keeps the level), from `start`'s move, each photo through its best colour
  // transform there.
  std::vector<Pose> FitEach(Backend* backend, VecId x, const GroupMove& start, const VolumeShape& level,
                            const std::vector<float>& params, const std::vector<std::string>& photos) const {
    GroupViews g = Views(photos, o_.fit_pixels);
    for (size_t i = 0; i < g.views.size(); ++i) SetPose(start.Apply(g.poses[i]), &g.views[i].camera);
    std::vector<ColourTransform<float>> transforms;
    ScoreExposed(backend, x, g.views, &transforms);
    const std::unique_ptr<Backend> fit_backend = MakeBackend(run_.options.device, run_.options.threads);
    const std::vector<PoseValues> values = FitViewPoses(fit_backend.get(), level, params, run_.geometry, g.views,
                                                        transforms, std::vector<PoseValues>(g.views.size()), {});
    std::vector<Pose> fitted;
    for (size_t i = 0; i < g.views.size(); ++i) {
      fitted.push_back(WorldFromCam(CorrectedCamera(g.views[i].camera, values[i].data(), run_.geometry)));
    }
    return fitted;
  }

  ReconstructRun& run_;
  const TurnSearchOptions& o_;
  const std::set<std::string>& marked_;
};

// The scene's images and the loaded photos of a group moved by t.move where used; its mark cleared either way.
void Apply(ReconstructRun& run, const TurnSearch& t) {
  const std::set<std::string> names(t.photos.begin(), t.photos.end());
  for (SceneImage& im : run.scene.images) {
    if (!names.count(im.name)) continue;
    im.turn_group = -1;
    im.pose_doubt = StrCat("moved onto the object with its ghost group by the repair (perf import); perf "
                           "reconstruct's search: ", t.why);
    if (!t.used) continue;
    im.world_from_cam = t.move.Apply(im.world_from_cam);
    const PinholeCamera<float> camera = ToPinhole(run.scene.camera(im.camera_id), im.world_from_cam);
    for (auto* photos : {&run.train, &run.test}) {
      for (PosedImage& p : *photos) {
        if (p.name == im.name) p.camera = camera;
      }
    }
  }
}

}  // namespace

nlohmann::json TurnSearch::ToJson() const {
  nlohmann::json rows = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) rows.push_back({move.rotation(i, 0), move.rotation(i, 1), move.rotation(i, 2)});
  return {{"group", group},
          {"photos", photos},
          {"scored", scored},
          {"turns_tried", turns_tried},
          {"turn_degrees", turn_degrees},
          {"psnr_before", psnr_before},
          {"psnr_turned", psnr_turned},
          {"psnr_fitted", psnr_fitted},
          {"psnr_moved", psnr_moved},
          {"used", used},
          {"chosen", used ? chosen : ""},
          {"turn_seconds", turn_seconds},
          {"fit_seconds", fit_seconds},
          {"move", {{"rotation", rows}, {"scale", move.scale}, {"shift", {move.shift.x(), move.shift.y(), move.shift.z()}}}},
          {"why", why}};
}

Pose GroupMove::Apply(const Pose& p) const {
  Pose out;
  out.leftCols<3>() = rotation * p.leftCols<3>();
  out.col(3) = scale * (rotation * p.col(3)) + shift;
  return out;
}

double GroupMove::Degrees() const { return ::perf::recon::Degrees(rotation); }

GroupMove GroupMove::Turn(const Eigen::Vector3d& pivot, const Eigen::Matrix3d& turn) {
  GroupMove m;
  m.rotation = turn;
  m.shift = pivot - turn * pivot;
  return m;
}

GroupMove GroupMove::Between(const std::vector<Pose>& from, const std::vector<Pose>& to) {
  PERF_CHECK(from.size() == to.size() && !from.empty());
  const size_t n = from.size();
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d mean_from = Eigen::Vector3d::Zero(), mean_to = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    sum += to[i].leftCols<3>() * from[i].leftCols<3>().transpose();
    mean_from += from[i].col(3) / static_cast<double>(n);
    mean_to += to[i].col(3) / static_cast<double>(n);
  }
  GroupMove m;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1;
  m.rotation = svd.matrixU() * d * svd.matrixV().transpose();
  double num = 0, den = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d a = m.rotation * (from[i].col(3) - mean_from), b = to[i].col(3) - mean_to;
    num += a.dot(b);
    den += a.squaredNorm();
  }
  m.scale = n > 1 && den > 0 && num > 0 ? num / den : 1;
  m.shift = mean_to - m.scale * (m.rotation * mean_from);
  return m;
}

Eigen::Matrix3d FindTurn(const std::function<double(const Eigen::Matrix3d&)>& score, const Eigen::Vector3d& up,
                         const Eigen::Vector3d& toward, const TurnSearchOptions& o, int* tried) {
  const Eigen::Vector3d u = up.normalized();
  Eigen::Vector3d radial = toward - toward.dot(u) * u;
  radial = radial.norm() > 1e-9 ? radial.normalized() : Eigen::Vector3d(u.unitOrthogonal());
  const Eigen::Vector3d across = u.cross(radial);
  int n = 0;
  Eigen::Matrix3d best = Eigen::Matrix3d::Identity();
  double best_score = score(best);
  ++n;
  const auto consider = [&](const Eigen::Matrix3d& turn) {
    const double s = score(turn);
    ++n;
    if (s > best_score) {
      best_score = s;
      best = turn;
    }
  };
  const int steps = std::max(1, static_cast<int>(std::lround(360 / o.step_degrees)));
  for (int k = 1; k < steps; ++k) consider(AxisTurn(u, 360.0 * k / steps));
  double step = 180.0 / steps;
  for (int round = 0; round < o.refinements; ++round, step /= 2) {
    const Eigen::Matrix3d centre = best;
    const Eigen::Vector3d a = centre * across, r = centre * radial;
    for (int i = -1; i <= 1; ++i) {
      for (int j = -1; j <= 1; ++j) {
        for (int k = -1; k <= 1; ++k) {
          if (i == 0 && j == 0 && k == 0) continue;
          consider(AxisTurn(u, i * step) * AxisTurn(a, j * step) * AxisTurn(r, k * step) * centre);
        }
      }
    }
  }
  if (tried != nullptr) *tried = n;
  return best;
}

std::vector<TurnSearch> SearchTurns(ReconstructRun& run, const TurnSearchOptions& o) {
  std::map<int, std::vector<std::string>> groups;
  std::set<std::string> marked;
  for (const SceneImage& im : run.scene.images) {
    if (im.turn_group < 0) continue;
    groups[im.turn_group].push_back(im.name);
    marked.insert(im.name);
  }
  if (groups.empty()) return {};
  if (run.comm.size() > 1) {
    run.Say("turn search: not run with several ranks; the groups' poses stay as imported (run one process once)");
    return {};
  }
  const Others others = OtherPhotos(run, marked);
  if (others.photos.empty()) {
    run.Say("turn search: every training photo is in a moved group; their poses stay as imported");
    return {};
  }
  run.Say(StrCat("turn search: ", groups.size(), " group(s) of ", marked.size(),
                 " photos moved onto the object by the repair; fitting the first level from the other ",
                 others.photos.size(), " training photos"));
  // The first level of the run's own hierarchy, on its downscale of the photos (a hierarchy of one
  // level would fit them whole: bonsai's 56 photos at 400 px took 246 s, not 15).
  const int factor = LevelDownscale(run.hierarchy, others.views, run.geometry, run.hierarchy.start_resolution, 0);
  const std::vector<PosedImage> fit_photos = factor > 1 ? DownscaledAll(others.photos, factor) : others.photos;
  HierarchyOptions h = run.hierarchy;
  h.levels = 1;
  h.exposures = 0;
  h.poses = 0;
  h.stop_when_out_of_memory = false;
  Searcher searcher(run, o, marked);
  std::vector<TurnSearch> found;
  HierarchyCallbacks cb;
  cb.level_done = [&](const HierarchyLevel& level, const SolverSummary&, const std::vector<float>& x) {
    for (const auto& [group, photos] : groups) {
      found.push_back(searcher.Search(run.backend.get(), level.params, level.shape, x, group, photos));
    }
  };
  const auto start = WallClock::now();
  SolveHierarchy(run.backend.get(), run.geometry, ViewsForHierarchy(fit_photos), h, HierarchyStart{}, cb);
  const double seconds = SecondsSince(start);
  double level_seconds = seconds;
  for (const TurnSearch& t : found) level_seconds -= t.turn_seconds + t.fit_seconds;
  run.Say(StrCat("turn search: ", std::lround(seconds), " s (the first level ", std::lround(level_seconds),
                 " s; the turns and the pose fits of each group the rest)"));
  for (const TurnSearch& t : found) {
    Apply(run, t);
    run.Say(StrCat("turn search: group ", t.group + 1, " (", t.photos.size(), " photos) ", t.why));
    run.log.Write({{"event", "turn_search"}, {"search", t.ToJson()}});
  }
  run.train_views = SplitViews(run.scene, Split::kTrain);
  if (run.root) WriteScene(run.scene_path, run.scene);
  return found;
}

}  // namespace perf::recon
