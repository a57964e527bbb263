// Undistortion to a pinhole that keeps only valid pixels.
//
// OpenCV proposes the new pinhole (getOptimalNewCameraMatrix with alpha = 0, or
// fisheye::estimateNewCameraMatrixForUndistortRectify with balance = 0), builds the remap tables
// and resamples. Neither proposal can be trusted as is. OpenCV 4.6's alpha = 0 camera samples
// 1 px beyond the input's outermost pixel centres on the test cameras (half a pixel outside the
// image), and it fits a rectangle to a 9 x 9 grid of iteratively undistorted points, which says
// nothing about a model that folds over inside the image. The fisheye one looks at the four edge
// midpoints only, and with fx != fy it mixes up the aspect ratio (2.5 px too conservative on a
// 640 x 480 test camera). So the proposal's focal lengths are rescaled about its principal
// point until it is the widest such pinhole whose every pixel is valid, judged with COLMAP's
// own forward model (camera_models.h), which is exact; BorderIsUsable and BuildAndCheckMaps say
// what valid means.
#include "sfm_import/undistort.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/errors.h"
#include "sfm_import/camera_models.h"

namespace perf {

struct Undistorter::Maps {
  colmap::CameraModelId model{};
  std::vector<double> params;  // COLMAP's, in the model's order
  std::string source;          // names the camera in messages
  // For each output pixel, where to sample the input, in OpenCV's pixel convention (upper-left
  // pixel centre at (0, 0)). CV_32FC1, height x width; empty for identity undistorters.
  cv::Mat map_x, map_y;
};

namespace {

using colmap::CameraModelId;

// How far outside the input's outermost pixel centres a sample may land: BORDER_REPLICATE
// makes that indistinguishable from sampling the edge pixel itself.
constexpr double kInsideTolerancePx = 1e-3;
// OpenCV's tables against COLMAP's formula. They agree to float rounding (~1e-3 px at
// 30000 px); anything larger means the models differ, which is a bug here.
constexpr double kMapAgreementPx = 1e-2;
// cv::remap addresses source pixels with 16-bit integers internally.
constexpr uint64_t kMaxSide = 32767;
// Pinhole images are not resampled; this only keeps sizes within int.
constexpr uint64_t kMaxPinholeSide = 1 << 20;
// Zoom factors beyond this mean the distortion leaves (almost) nothing usable.
constexpr double kMaxZoom = 100;
// OpenCV's proposals are never this conservative; the search stops here.
constexpr double kMinZoom = 0.5;

constexpr const char* kUndistortHint =
    "Undistort the images first with `colmap image_undistorter` and import the undistorted "
    "model";

bool IsFisheye(CameraModelId id) {
  return id == CameraModelId::kOpenCVFisheye || id == CameraModelId::kSimpleRadialFisheye ||
         id == CameraModelId::kRadialFisheye;
}

std::string SupportedModelNames() {
  std::string names;
  for (int id = 0; const colmap::CameraModelInfo* m = colmap::FindCameraModel(id); ++id) {
    if (!m->supported) continue;
    if (!names.empty()) names += ", ";
    names += m->name;
  }
  return names;
}

// OpenCV's distortion coefficients for a COLMAP model: (k1, k2, p1, p2[, k3, k4, k5, k6]) for
// the perspective models, (k1, k2, k3, k4) for the fisheye ones. The formulas agree term by term
// with camera_models.h (FULL_OPENCV is OpenCV's rational model with the same coefficient order);
// BuildAndCheckMaps verifies that on every pixel.
std::vector<double> OpenCvDistortion(CameraModelId id, const std::vector<double>& params) {
  const double* e = params.data() + colmap::NumFocalParams(id);
  switch (id) {
    case CameraModelId::kSimpleRadial:
    case CameraModelId::kSimpleRadialFisheye:
      return {e[0], 0, 0, 0};
    case CameraModelId::kRadial:
    case CameraModelId::kRadialFisheye:
      return {e[0], e[1], 0, 0};
    case CameraModelId::kOpenCV:
    case CameraModelId::kOpenCVFisheye:
      return {e[0], e[1], e[2], e[3]};
    case CameraModelId::kFullOpenCV:
      return {e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7]};
    default:
      PERF_CHECK_MSG(false, "no OpenCV distortion for model ", static_cast<int>(id));
      return {};
  }
}

// PERF's pixel centres are OpenCV's plus 0.5 (camera_models.h).
cv::Matx33d ToOpenCvK(double fx, double fy, double cx, double cy) {
  return {fx, 0, cx - 0.5, 0, fy, cy - 0.5, 0, 0, 1};
}

struct Model {
  CameraModelId id;
  const std::vector<double>& params;
  int width, height;
};

void DistortedPixel(const Model& m, const PinholeIntrinsics& p, double x, double y, double* xd,
                    double* yd) {
  colmap::ImgFromCam(m.id, m.params.data(), (x - p.cx) / p.fx, (y - p.cy) / p.fy, 1.0, xd, yd);
}

// Between the input's outermost pixel centres, so bilinear interpolation reads real pixels.
bool InsideInput(const Model& m, double xd, double yd) {
  return xd >= 0.5 - kInsideTolerancePx && xd <= m.width - 0.5 + kInsideTolerancePx &&
         yd >= 0.5 - kInsideTolerancePx && yd <= m.height - 0.5 + kInsideTolerancePx;
}

// Orientation test: the polynomial models fold over past some radius (e.g. 1 + k1 r^2 with
// k1 < 0), mapping rays beyond the fold back into the image at the wrong place; there the
// Jacobian determinant of output pixel -> input pixel is not positive.
bool NotFolded(double dxd_dx, double dyd_dx, double dxd_dy, double dyd_dy) {
  return dxd_dx * dyd_dy - dxd_dy * dyd_dx > 0;
}

// Whether every border pixel centre of pinhole `p` samples inside the input, unfolded.
// For the radial models the worst pixels are on the border (the radius is largest there), so
// this is the cheap test used to choose the zoom; BuildAndCheckMaps then checks every pixel.
bool BorderIsUsable(const Model& m, const PinholeIntrinsics& p) {
  constexpr double h = 0.25;  // finite-difference step, output pixels
  auto usable = [&](double x, double y) {
    double xd, yd, x0, y0, x1, y1, x2, y2, x3, y3;
    DistortedPixel(m, p, x, y, &xd, &yd);
    if (!InsideInput(m, xd, yd)) return false;
    DistortedPixel(m, p, x - h, y, &x0, &y0);
    DistortedPixel(m, p, x + h, y, &x1, &y1);
    DistortedPixel(m, p, x, y - h, &x2, &y2);
    DistortedPixel(m, p, x, y + h, &x3, &y3);
    return NotFolded(x1 - x0, y1 - y0, x3 - x2, y3 - y2);
  };
  for (int i = 0; i < p.width; ++i) {
    if (!usable(i + 0.5, 0.5) || !usable(i + 0.5, p.height - 0.5)) return false;
  }
  for (int j = 0; j < p.height; ++j) {
    if (!usable(0.5, j + 0.5) || !usable(p.width - 0.5, j + 0.5)) return false;
  }
  return true;
}

// Larger focal lengths about the same principal point: the output sees a narrower cone around
// the ray through its principal point. That ray is the optical axis, which lands on the input's
// principal point (checked to be inside the image), so a large enough zoom is always usable.
PinholeIntrinsics Zoomed(PinholeIntrinsics p, double zoom) {
  p.fx *= zoom;
  p.fy *= zoom;
  return p;
}

// The smallest zoom (to 1e-6) at which the border of `p` is usable, searched from OpenCV's
// proposal (zoom 1) in both directions: up where the proposal reaches outside the input, down
// where it crops more than it has to. Nullopt if even kMaxZoom is not usable.
std::optional<double> SmallestUsableZoom(const Model& m, const PinholeIntrinsics& p) {
  const auto usable = [&](double zoom) { return BorderIsUsable(m, Zoomed(p, zoom)); };
  double lo, hi;  // border not usable at lo, usable at hi
  if (usable(1)) {
    hi = 1;
    for (double step = 1e-3;; step *= 2) {
      lo = 1 - step;
      if (lo < kMinZoom) return hi;
      if (!usable(lo)) break;
      hi = lo;
    }
  } else {
    lo = 1;
    for (double step = 1e-3;; step *= 2) {
      hi = 1 + step;
      if (hi > kMaxZoom) return std::nullopt;
      if (usable(hi)) break;
      lo = hi;
    }
  }
  while (hi - lo > 1e-6) {
    const double mid = 0.5 * (lo + hi);
    (usable(mid) ? hi : lo) = mid;
  }
  return hi;
}

// OpenCV's proposal for the new pinhole (see the top of the file), in PERF's conventions. Falls
// back to the camera's own intrinsics if OpenCV returns something unusable (its iterative
// undistortion can diverge for extreme coefficients); the zoom search then does the work.
PinholeIntrinsics ProposePinhole(const Model& m, const cv::Matx33d& K,
                                 const std::vector<double>& D, const PinholeIntrinsics& own) {
  const cv::Size size(m.width, m.height);
  cv::Matx33d k_new;
  if (IsFisheye(m.id)) {
    cv::Mat out;
    cv::fisheye::estimateNewCameraMatrixForUndistortRectify(K, D, size, cv::Matx33d::eye(), out,
                                                            /*balance=*/0.0, size);
    k_new = out;
  } else {
    k_new = cv::getOptimalNewCameraMatrix(K, D, size, /*alpha=*/0.0, size, nullptr,
                                          /*centerPrincipalPoint=*/false);
  }
  PinholeIntrinsics p = own;
  p.fx = k_new(0, 0);
  p.fy = k_new(1, 1);
  p.cx = k_new(0, 2) + 0.5;
  p.cy = k_new(1, 2) + 0.5;
  const bool finite = std::isfinite(p.fx) && std::isfinite(p.fy) && std::isfinite(p.cx) &&
                      std::isfinite(p.cy);
  if (!finite || p.fx <= 0 || p.fy <= 0) return own;
  double xd, yd;
  DistortedPixel(m, p, p.cx, p.cy, &xd, &yd);  // must be the input's principal point
  if (!InsideInput(m, xd, yd)) return own;
  return p;
}

// Fills `map_x` / `map_y` with OpenCV for pinhole `p`, compares every entry with COLMAP's
// formula and returns whether every output pixel is usable (inside the input, unfolded).
bool BuildAndCheckMaps(const Model& m, const cv::Matx33d& K, const std::vector<double>& D,
                       const PinholeIntrinsics& p, const std::string& model_name, cv::Mat* map_x,
                       cv::Mat* map_y) {
  const cv::Size size(m.width, m.height);
  const cv::Matx33d k_new = ToOpenCvK(p.fx, p.fy, p.cx, p.cy);
  if (IsFisheye(m.id)) {
    cv::fisheye::initUndistortRectifyMap(K, D, cv::Matx33d::eye(), k_new, size, CV_32FC1,
                                         *map_x, *map_y);
  } else {
    cv::initUndistortRectifyMap(K, D, cv::noArray(), k_new, size, CV_32FC1, *map_x, *map_y);
  }
  PERF_CHECK(map_x->type() == CV_32FC1 && map_y->type() == CV_32FC1 &&
             map_x->size() == size && map_y->size() == size);

  // Per-row results, so rows can be checked in parallel without shared mutable state.
  std::vector<char> row_usable(m.height, 1);
  std::vector<double> row_disagreement(m.height, 0);
  cv::parallel_for_(cv::Range(0, m.height), [&](const cv::Range& rows) {
    for (int j = rows.start; j < rows.end; ++j) {
      const int j_down = std::min(j + 1, m.height - 1);
      const float* mx = map_x->ptr<float>(j);
      const float* my = map_y->ptr<float>(j);
      const float* mx_down = map_x->ptr<float>(j_down);
      const float* my_down = map_y->ptr<float>(j_down);
      for (int i = 0; i < m.width; ++i) {
        double xd, yd;
        DistortedPixel(m, p, i + 0.5, j + 0.5, &xd, &yd);
        row_disagreement[j] = std::max({row_disagreement[j], std::abs(mx[i] + 0.5 - xd),
                                        std::abs(my[i] + 0.5 - yd)});
        bool usable = InsideInput(m, xd, yd);
        // Forward differences of the table between neighbouring pixels: ~1 px apart, so float
        // rounding (~1e-3 px) cannot flip the sign of an unfolded determinant.
        if (i + 1 < m.width && j + 1 < m.height) {
          usable = usable && NotFolded(mx[i + 1] - mx[i], my[i + 1] - my[i], mx_down[i] - mx[i],
                                       my_down[i] - my[i]);
        }
        if (!usable) row_usable[j] = 0;
      }
    }
  });
  const double disagreement =
      *std::max_element(row_disagreement.begin(), row_disagreement.end());
  PERF_CHECK_MSG(disagreement < kMapAgreementPx, "OpenCV's undistortion table for ", model_name,
                 " differs from COLMAP's formula by ", disagreement, " px");
  return std::all_of(row_usable.begin(), row_usable.end(), [](char ok) { return ok != 0; });
}

}  // namespace

Undistorter::Undistorter(Undistorter&&) noexcept = default;
Undistorter& Undistorter::operator=(Undistorter&&) noexcept = default;
Undistorter::~Undistorter() = default;

Undistorter Undistorter::Create(const colmap::Camera& camera, const std::string& source) {
  const colmap::CameraModelInfo* info = colmap::FindCameraModel(camera.model_id);
  if (info == nullptr) {
    throw InputError(source, "model_id", std::to_string(camera.model_id),
                     "unknown camera model (PERF undistorts " + SupportedModelNames() + ")",
                     kUndistortHint);
  }
  const std::string name(info->name);
  if (!info->supported) {
    throw InputError(source, "model", name,
                     "PERF cannot undistort this camera model (it undistorts " +
                         SupportedModelNames() + ")",
                     kUndistortHint);
  }
  if (camera.params.size() != static_cast<size_t>(info->num_params)) {
    throw InputError(source, "params", StrCat(camera.params.size(), " values"),
                     StrCat(name, " takes ", info->num_params, " parameters (", info->params,
                            ")"),
                     "Re-export the model from COLMAP");
  }
  for (size_t i = 0; i < camera.params.size(); ++i) {
    if (!std::isfinite(camera.params[i])) {
      throw InputError(source, StrCat("params[", i, "]"), StrCat(camera.params[i]),
                       "camera parameters must be finite");
    }
  }
  if (camera.width == 0 || camera.height == 0 || camera.width > kMaxPinholeSide ||
      camera.height > kMaxPinholeSide) {
    throw InputError(source, "width x height", StrCat(camera.width, "x", camera.height),
                     StrCat("image sides must be between 1 and ", kMaxPinholeSide, " pixels"));
  }
  const colmap::FocalAndCentre fc = colmap::GetFocalAndCentre(info->id, camera.params.data());
  if (fc.fx <= 0 || fc.fy <= 0) {
    throw InputError(source, "focal length", StrCat(fc.fx, ", ", fc.fy),
                     "focal lengths must be positive");
  }

  Undistorter u;
  u.maps_ = std::make_unique<Maps>();
  u.maps_->model = info->id;
  u.maps_->params = camera.params;
  u.maps_->source = source;
  const int width = static_cast<int>(camera.width), height = static_cast<int>(camera.height);
  const PinholeIntrinsics own{width, height, fc.fx, fc.fy, fc.cx, fc.cy};
  if (info->id == CameraModelId::kSimplePinhole || info->id == CameraModelId::kPinhole) {
    u.pinhole_ = own;
    u.identity_ = true;
    return u;
  }

  if (camera.width > kMaxSide || camera.height > kMaxSide) {
    throw InputError(source, "width x height", StrCat(camera.width, "x", camera.height),
                     StrCat("PERF resamples images of up to ", kMaxSide,
                            " pixels a side (OpenCV's remap limit)"),
                     kUndistortHint);
  }
  const Model m{info->id, u.maps_->params, width, height};
  const auto no_usable_view = [&] {
    std::string values;
    for (double v : camera.params) values += (values.empty() ? "" : ", ") + StrCat(v);
    return InputError(source, "params", values,
                      StrCat("this ", name, " distortion leaves no usable pinhole view of the ",
                             width, "x", height, " image"),
                      "Check the camera's parameters; if they are right, " +
                          std::string(kUndistortHint));
  };
  // The zoom search converges only if the optical axis lands inside the image.
  if (!InsideInput(m, fc.cx, fc.cy)) {
    throw InputError(source, "principal point", StrCat(fc.cx, ", ", fc.cy),
                     StrCat("lies outside the ", width, "x", height, " image"),
                     "Check the camera's parameters");
  }
  const cv::Matx33d K = ToOpenCvK(fc.fx, fc.fy, fc.cx, fc.cy);
  const std::vector<double> D = OpenCvDistortion(info->id, camera.params);
  const PinholeIntrinsics proposed = ProposePinhole(m, K, D, own);
  const std::optional<double> border_zoom = SmallestUsableZoom(m, proposed);
  if (!border_zoom) throw no_usable_view();
  // The border test suffices for distortion that grows with the radius; a model that folds
  // inside the image (several turning points) needs more zoom, found here in 5% steps.
  for (double zoom = *border_zoom;; zoom *= 1.05) {
    if (zoom > kMaxZoom) throw no_usable_view();
    u.pinhole_ = Zoomed(proposed, zoom);
    if (BuildAndCheckMaps(m, K, D, u.pinhole_, name, &u.maps_->map_x, &u.maps_->map_y)) break;
  }
  return u;
}

Image Undistorter::Apply(const Image& in) const {
  PERF_CHECK_MSG(maps_ != nullptr, "Apply on a moved-from Undistorter");
  if (in.width != pinhole_.width || in.height != pinhole_.height) {
    throw InputError(maps_->source, "image size", StrCat(in.width, "x", in.height),
                     StrCat("does not match the camera's ", pinhole_.width, "x",
                            pinhole_.height),
                     "Import the images the model was reconstructed from, at their original "
                     "resolution");
  }
  PERF_CHECK(in.channels >= 1 && in.channels <= CV_CN_MAX &&
             in.pixels.size() == static_cast<size_t>(in.width) * in.height * in.channels);
  if (identity_) return in;

  Image out(in.width, in.height, in.channels);
  // Views, no copies; remap only reads `src`.
  const cv::Mat src(in.height, in.width, CV_32FC(in.channels),
                    const_cast<float*>(in.pixels.data()));
  cv::Mat dst(out.height, out.width, CV_32FC(out.channels), out.pixels.data());
  // Every sample is inside the input (Create), so the border mode only matters within
  // kInsideTolerancePx of the edge. remap quantises positions to 1/32 px (INTER_BITS), an
  // error of at most 1/64 px.
  cv::remap(src, dst, maps_->map_x, maps_->map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  PERF_CHECK(dst.data == reinterpret_cast<const uchar*>(out.pixels.data()));
  return out;
}

void Undistorter::MapToDistorted(double x, double y, double* xd, double* yd) const {
  PERF_CHECK_MSG(maps_ != nullptr, "MapToDistorted on a moved-from Undistorter");
  if (identity_) {
    *xd = x;
    *yd = y;
    return;
  }
  // COLMAP's forward model rather than the float tables: exact, and defined between pixels.
  const Model m{maps_->model, maps_->params, pinhole_.width, pinhole_.height};
  DistortedPixel(m, pinhole_, x, y, xd, yd);
}

void Undistorter::MapFromDistorted(std::vector<float>* x, std::vector<float>* y) const {
  PERF_CHECK_MSG(maps_ != nullptr, "MapFromDistorted on a moved-from Undistorter");
  const int width = pinhole_.width, height = pinhole_.height;
  const size_t count = static_cast<size_t>(width) * height;
  x->resize(count);
  y->resize(count);
  if (identity_) {
    for (int j = 0; j < height; ++j) {
      for (int i = 0; i < width; ++i) {
        (*x)[static_cast<size_t>(j) * width + i] = static_cast<float>(i + 0.5);
        (*y)[static_cast<size_t>(j) * width + i] = static_cast<float>(j + 0.5);
      }
    }
    return;
  }
  // OpenCV's iterative undistortion gives the start; Newton steps on COLMAP's exact forward
  // model (as MapToDistorted) polish it, and points that do not come back to their pixel
  // (beyond a fold of the model) are NaN.
  const colmap::FocalAndCentre fc = colmap::GetFocalAndCentre(maps_->model, maps_->params.data());
  const cv::Matx33d K = ToOpenCvK(fc.fx, fc.fy, fc.cx, fc.cy);
  const cv::Matx33d k_new = ToOpenCvK(pinhole_.fx, pinhole_.fy, pinhole_.cx, pinhole_.cy);
  const std::vector<double> D = OpenCvDistortion(maps_->model, maps_->params);
  const Model m{maps_->model, maps_->params, width, height};
  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& rows) {
    std::vector<cv::Point2d> in(width), out;
    for (int j = rows.start; j < rows.end; ++j) {
      for (int i = 0; i < width; ++i) in[i] = {static_cast<double>(i), static_cast<double>(j)};
      const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 50, 1e-10);
      if (IsFisheye(m.id)) {
        cv::fisheye::undistortPoints(in, out, K, D, cv::noArray(), k_new, criteria);
      } else {
        cv::undistortPoints(in, out, K, D, cv::noArray(), k_new, criteria);
      }
      for (int i = 0; i < width; ++i) {
        const double xd_target = i + 0.5, yd_target = j + 0.5;
        double px = out[i].x + 0.5, py = out[i].y + 0.5;
        double err = 0;
        for (int it = 0; it < 5; ++it) {
          constexpr double h = 1e-3;
          double xd, yd, x1, y1, x2, y2;
          DistortedPixel(m, pinhole_, px, py, &xd, &yd);
          DistortedPixel(m, pinhole_, px + h, py, &x1, &y1);
          DistortedPixel(m, pinhole_, px, py + h, &x2, &y2);
          const double a = (x1 - xd) / h, b = (x2 - xd) / h, c = (y1 - yd) / h, d = (y2 - yd) / h;
          const double ex = xd - xd_target, ey = yd - yd_target, det = a * d - b * c;
          err = std::max(std::abs(ex), std::abs(ey));
          if (err < 1e-6 || !(det > 0)) break;
          px -= (d * ex - b * ey) / det;
          py -= (-c * ex + a * ey) / det;
        }
        const bool ok = std::isfinite(px) && std::isfinite(py) && err < 1e-2;
        const size_t k = static_cast<size_t>(j) * width + i;
        (*x)[k] = ok ? static_cast<float>(px) : std::numeric_limits<float>::quiet_NaN();
        (*y)[k] = ok ? static_cast<float>(py) : std::numeric_limits<float>::quiet_NaN();
      }
    }
  });
}

}  // namespace perf
