#include "sfm_import/ghost_groups.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <set>
#include <unordered_map>

#include "common/errors.h"

namespace perf {
namespace {

Eigen::Vector3d Xyz(const colmap::Point3D& p) { return {p.xyz[0], p.xyz[1], p.xyz[2]}; }

bool InBox(const SceneBox& box, const Eigen::Vector3d& p) {
  const Eigen::Vector3d local = box.rotation.transpose() * (p - box.center);
  return (local.array().abs() <= 0.5 * box.size.array()).all();
}

// Union-find over dense indices.
struct Groups {
  std::vector<int> parent;
  explicit Groups(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  }
  void Join(int a, int b) { parent[Find(a)] = Find(b); }
};

struct Cluster {
  std::vector<int> photos;
  std::vector<uint64_t> points;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0;
};

}  // namespace

std::string GhostGroup::Describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%.2g units (%.1f times the object's radius)", separation,
                main_radius > 0 ? separation / main_radius : 0.0);
  const std::string span = names.empty() ? "" : StrCat(names.front(), " ... ", names.back());
  return StrCat(names.size(), " photos (", span, ") see ", points, " sparse points inside the box ", buf, " from the ",
                main_points, " that the other ", main_photos, " photos see, and share none");
}

std::string GhostGroup::Warning() const {
  std::string list;
  for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
  return StrCat(Describe(), ": COLMAP reconstructed the object twice, so these photos' poses disagree with the ",
                "others', and the volume shows a blurred or second object from their side (camera refinement ",
                "corrects only part of such an error). They are kept for training (without them nothing sees that ",
                "side). To fix it, make the model again (perf sfm --images DIR matches the photos in capture order; ",
                "on a capture with such a group it tied the group to the rest), or remove them from a copy of the ",
                "model (colmap image_deleter). The photos: ", list);
}

std::string GhostGroup::Doubt() const {
  return StrCat("in a group that sees the object elsewhere: ", Describe(),
                "; COLMAP placed the object elsewhere for them (a ghost), so their poses disagree with the others'");
}

std::vector<GhostGroup> FindGhostGroups(const colmap::Reconstruction& rec, const SceneBox& box,
                                        const std::map<std::string, std::string>& left_out,
                                        const GhostGroupOptions& o) {
  // The photos taking part, densely numbered, and which of them see each in-box point.
  std::vector<const colmap::Image*> photos;
  std::map<uint64_t, std::vector<int>> seen_by;  // in-box point -> photos
  for (const auto& [id, im] : rec.images) {
    if (left_out.count(im.name)) continue;
    const int k = static_cast<int>(photos.size());
    photos.push_back(&im);
    for (const colmap::Point2D& p : im.points2D) {
      if (p.point3D_id == colmap::kInvalidPoint3DId) continue;  // most of a photo's 2-D points
      const auto it = rec.points3D.find(p.point3D_id);
      if (it == rec.points3D.end()) continue;
      if (!InBox(box, Xyz(it->second))) continue;
      std::vector<int>& v = seen_by[p.point3D_id];
      if (v.empty() || v.back() != k) v.push_back(k);
    }
  }
  Groups groups(static_cast<int>(photos.size()));
  if (o.min_shared_points <= 1) {  // one shared point links: a point joins all who see it
    for (const auto& [id, v] : seen_by) {
      for (size_t a = 1; a < v.size(); ++a) groups.Join(v[0], v[a]);
    }
  } else {  // count the points each pair shares (a track of T photos makes T (T - 1) / 2 pairs)
    std::unordered_map<uint64_t, int> shared;
    for (const auto& [id, v] : seen_by) {
      for (size_t a = 0; a < v.size(); ++a) {
        for (size_t b = a + 1; b < v.size(); ++b) {
          const uint64_t key = static_cast<uint64_t>(std::min(v[a], v[b])) << 32 | std::max(v[a], v[b]);
          if (++shared[key] >= o.min_shared_points) groups.Join(v[a], v[b]);
        }
      }
    }
  }
  // Each group's photos and in-box points (a point seen by two groups, which only happens when
  // min_shared_points > 1, counts in both).
  std::map<int, Cluster> clusters;
  for (int k = 0; k < static_cast<int>(photos.size()); ++k) clusters[groups.Find(k)].photos.push_back(k);
  for (const auto& [id, v] : seen_by) {
    std::vector<int> roots;
    for (int k : v) roots.push_back(groups.Find(k));
    std::sort(roots.begin(), roots.end());
    roots.erase(std::unique(roots.begin(), roots.end()), roots.end());
    for (int r : roots) clusters[r].points.push_back(id);
  }
  std::vector<Cluster> list;
  for (auto& [root, c] : clusters) {
    if (c.points.empty()) continue;
    for (uint64_t id : c.points) c.centre += Xyz(rec.points3D.at(id));
    c.centre /= static_cast<double>(c.points.size());
    double sum = 0;
    for (uint64_t id : c.points) sum += (Xyz(rec.points3D.at(id)) - c.centre).squaredNorm();
    c.radius = std::sqrt(sum / static_cast<double>(c.points.size()));
    list.push_back(std::move(c));
  }
  if (list.size() < 2) return {};
  std::sort(list.begin(), list.end(), [](const Cluster& a, const Cluster& b) {
    return a.photos.size() != b.photos.size() ? a.photos.size() > b.photos.size() : a.points.size() > b.points.size();
  });
  const Cluster& main = list.front();
  std::vector<GhostGroup> out;
  for (size_t i = 1; i < list.size(); ++i) {
    const Cluster& c = list[i];
    const double separation = (c.centre - main.centre).norm();
    if (static_cast<int>(c.photos.size()) < o.min_photos || static_cast<int>(c.points.size()) < o.min_points ||
        separation <= o.min_separation * main.radius) {
      continue;
    }
    GhostGroup g;
    for (int k : c.photos) g.names.push_back(photos[k]->name);
    std::sort(g.names.begin(), g.names.end());
    g.points = static_cast<int>(c.points.size());
    g.separation = separation;
    g.main_radius = main.radius;
    g.main_photos = static_cast<int>(main.photos.size());
    g.main_points = static_cast<int>(main.points.size());
    for (int k = 0; k < 3; ++k) g.centre[k] = c.centre[k], g.main_centre[k] = main.centre[k];
    out.push_back(std::move(g));
  }
  return out;
}

std::vector<std::string> MarkGhostGroups(const colmap::Reconstruction& rec,
                                         const std::map<std::string, std::string>& left_out, Scene* scene) {
  std::vector<std::string> warnings;
  for (const GhostGroup& g : FindGhostGroups(rec, scene->box, left_out)) {
    warnings.push_back(g.Warning());
    for (SceneImage& im : scene->images) {
      if (std::binary_search(g.names.begin(), g.names.end(), im.name)) im.pose_doubt = g.Doubt();
    }
  }
  return warnings;
}

void MarkTurnUnknown(const std::vector<std::vector<std::string>>& groups, Scene* scene) {
  for (size_t k = 0; k < groups.size(); ++k) {
    const std::set<std::string> names(groups[k].begin(), groups[k].end());
    for (SceneImage& im : scene->images) {
      if (!names.count(im.name)) continue;
      im.turn_group = static_cast<int>(k);
      im.pose_doubt = StrCat("moved onto the object with the ", names.size(),
                             " photos of its ghost group by the repair (perf import); its turn about the object "
                             "is not known: perf reconstruct searches it against the other photos");
    }
  }
}

}  // namespace perf
