#include "sfm_import/capture_order.h"

#include "common/errors.h"

namespace perf {

bool CaptureOrder::Known() const { return pairs >= 2 && with_time * 10 >= photos * 9; }

bool CaptureOrder::NamesFollowTime() const { return Known() && backwards * 10 <= pairs; }

std::string CaptureOrder::Describe() const {
  if (!Known()) {
    return StrCat(with_time, " of ", photos, " photos carry an EXIF capture time, too few to tell whether the file "
                  "names follow the capture: sequential matching first");
  }
  const std::string counted = StrCat(backwards, " of ", pairs, " consecutive photos by name go back in time");
  return NamesFollowTime() ? StrCat("the EXIF capture times follow the file names (", counted, "): sequential matching")
                           : StrCat("the EXIF capture times do not follow the file names (", counted,
                                    "): matching every pair");
}

CaptureOrder OrderFromTimes(const std::vector<std::string>& times) {
  CaptureOrder o;
  o.photos = static_cast<int>(times.size());
  for (size_t i = 0; i < times.size(); ++i) {
    if (times[i].empty()) continue;
    ++o.with_time;
    if (i > 0 && !times[i - 1].empty()) {
      ++o.pairs;
      // The fixed-width EXIF form orders as text does.
      if (times[i] < times[i - 1]) ++o.backwards;
    }
  }
  return o;
}

CaptureOrder OrderFromTags(const std::vector<std::optional<CameraTags>>& tags) {
  std::vector<std::string> times;
  times.reserve(tags.size());
  for (const std::optional<CameraTags>& t : tags) times.push_back(t ? t->time : std::string());
  return OrderFromTimes(times);
}

}  // namespace perf
