#include "recon_cuda/run/photo_fit.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "common/errors.h"
#include "recon_cuda/run/evaluation.h"

namespace perf::recon {

std::string PhotoFits::Warning(const PhotoFitOptions& o) const {
  if (poor.empty()) return {};
  std::string list;
  for (const PhotoFit& f : poor) {
    char psnr[32];
    std::snprintf(psnr, sizeof psnr, "%.1f dB", f.psnr);
    list += StrCat(list.empty() ? "" : ", ", f.name, " ", psnr);
  }
  char median[32];
  std::snprintf(median, sizeof median, "%.1f dB", median_psnr);
  return StrCat(poor.size(), poor.size() == 1 ? " training photo fits" : " training photos fit", " more than ",
                o.max_db_below_median, " dB worse than the median photo (", median, ") after the first level: ", list,
                ". Their poses may be off, or they show what the others do not (motion, blur); they stay in "
                "training. To leave one out, set its \"split\" to \"excluded\" in scene.json");
}

nlohmann::json PhotoFits::ToJson(const PhotoFitOptions& o) const {
  nlohmann::json list = nlohmann::json::array();
  for (const PhotoFit& f : poor) list.push_back({{"name", f.name}, {"psnr", f.psnr}});
  return {{"after_level", 1},
          {"median_psnr", median_psnr},
          {"max_db_below_median", o.max_db_below_median},
          {"poor", list}};
}

PhotoFits FindPoorFits(std::vector<PhotoFit> fits, const PhotoFitOptions& o) {
  PhotoFits out;
  if (fits.size() < 3) return out;
  std::sort(fits.begin(), fits.end(), [](const PhotoFit& a, const PhotoFit& b) { return a.psnr < b.psnr; });
  const size_t n = fits.size();
  out.median_psnr = n % 2 ? fits[n / 2].psnr : 0.5 * (fits[n / 2 - 1].psnr + fits[n / 2].psnr);
  for (const PhotoFit& f : fits) {
    if (f.psnr >= out.median_psnr - o.max_db_below_median) break;
    out.poor.push_back(f);
  }
  return out;
}

PhotoFits CheckPhotoFits(Backend* backend, VecId x, const std::vector<PosedImage>& share,
                         const std::vector<std::string>& names, const PhotoCorrections& exposures, Communicator& comm,
                         const PhotoFitOptions& o) {
  std::map<std::string, size_t> index;
  for (size_t i = 0; i < names.size(); ++i) index[names[i]] = i;
  std::vector<double> psnr(names.size(), 0.0);  // each rank fills its own photos' entries
  for (const ViewScore& s : ScoreViews(backend, x, share, 0.f, exposures)) {
    const auto it = index.find(s.name);
    PERF_CHECK_MSG(it != index.end(), "a training photo of this rank is among the names");
    psnr[it->second] = s.psnr;
  }
  comm.SumInPlace(psnr);
  std::vector<PhotoFit> fits;
  for (size_t i = 0; i < names.size(); ++i) fits.push_back({names[i], psnr[i]});
  return FindPoorFits(std::move(fits), o);
}

}  // namespace perf::recon
