// What the photos' EXIF capture times say of their file-name order. Sequential
// matching pairs each photo with its neighbours by name, which is right only when the names follow
// the capture (a walk around the object). Where the photos carry DateTimeOriginal, the times say
// whether they do before any matching is spent; without times, the first model's size is the
// evidence (colmap_runner.cc).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "workspace/image_io.h"

namespace perf {

struct CaptureOrder {
  int photos = 0;     // photos in name order
  int with_time = 0;  // of them with an EXIF capture time
  int pairs = 0;      // consecutive photos by name that both have a time
  int backwards = 0;  // of those pairs, the ones whose time goes back
  // Whether the times are evidence: 90 % of the photos or more carry one, and 2 pairs or more.
  bool Known() const;
  // Known, and at most 10 % of the pairs go back in time (bursts with equal times are in order).
  bool NamesFollowTime() const;
  // A line for the run: what the times say and which matching that means.
  std::string Describe() const;
};

// times: "YYYY:MM:DD HH:MM:SS" (EXIF DateTimeOriginal) of the photos in name order, "" where none.
CaptureOrder OrderFromTimes(const std::vector<std::string>& times);

// The same from the photos' header tags in name order (camera_groups.h ReadPhotoTags); a photo
// without tags counts as one without a time.
CaptureOrder OrderFromTags(const std::vector<std::optional<CameraTags>>& tags);

}  // namespace perf
