// The CUDA backend's Jacobian record (ray_record.h) run on the host: the code its kernels run
// (RecordWriter in Linearize's Backward sweep, FinishRecord, RecordedExposure, RecordedJtJp) over
// host arrays, in the order LinearizeKernel and JtJpRecordKernel call it (cuda_passes.cu), against
// the CPU backend's compact record (the same bfloat16 values from the same float partials: equal
// but for the order of the float sums) and its exact record (within the compact record's 3e-3:
// cpu_backend_test CompactRecordIsTheExactOneRoundedToBfloat16), on a dense level, a sparse one,
// with spherical harmonics, with exposures, poses and the robust loss, on every ray and on a
// subset, on every parameter and restricted to the free ones. Runs everywhere (no GPU); the
// device's own run of it is gpu_parity_test's RecordedJtJp cases.
#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/backends/device_record_plan.h"
#include "recon_cuda/core/ray_record.h"
#include "recon_cuda/core/training_ray.h"
#include "recon_cuda/data/volume.h"
#include "tests/recon/recon_test_util.h"

namespace perf::recon {
namespace {

using test::TinyProblem;

struct HostSink {
  std::vector<float>* out;
  void Add4(int64_t i, float a, float b, float c, float d) {
    float* p = out->data() + i;
    p[0] += a;
    p[1] += b;
    p[2] += c;
    p[3] += d;
  }
};

// The record's arrays on the host, for the rays of `jtj`.
struct HostRecord {
  std::vector<CompactSampleJ> packed;
  std::vector<uint8_t> steps;
  std::vector<RayRecordHead> heads;
  std::vector<float> h;
  std::vector<uint16_t> pose;
  unsigned long long used = 0;
  RecordView view;

  HostRecord(const LevelProblem& level, int64_t capacity, RaySubset jtj) {
    const int64_t slots = level.rays->size() / jtj.stride + 1;
    packed.resize(capacity);
    steps.resize(capacity);
    heads.resize(slots, RayRecordHead{-2, 0, 0, 0, 0.f, 0.f, 0.f, 0.f});
    h.resize(level.shape.exposures > 0 ? 3 * slots : 0);
    pose.resize(level.shape.poses > 0 ? kPoseRowValues * slots : 0);
    view = {packed.data(), steps.data(), capacity, &used, heads.data(), h.empty() ? nullptr : h.data(),
            pose.empty() ? nullptr : pose.data(), jtj.stride, jtj.offset};
  }
};

TrainingRays<float> RaysOf(const LevelProblem& level) {
  const RaySet& r = *level.rays;
  return {r.cameras.data(),
          r.pixels.data(),
          r.colours.data(),
          UsesAlpha(level) ? r.alphas.data() : nullptr,
          r.size(),
          r.first_index,
          level.shape.exposures > 0 ? r.exposure_slot.data() : nullptr,
          level.shape.poses > 0 ? r.exposure_slot.data() : nullptr};
}

// Only records (Linearize's scatters are the CPU backend's business here).
struct RecordOnlyVisitor {
  RecordWriter& w;
  void Shell(int, const CubeCoord<float>&, const TexelSample<float>&, const ShellPartials<float>&) {}
  void Sample(int k, const MarchStep<float>&, const GridSample<float>&, const SamplePartials<float>& sp) {
    w.Sample(k, sp);
  }
};

// Linearize's recording at x and seed, ray by ray as LinearizeKernel records them.
void Record(const LevelProblem& level, const std::vector<float>& x, uint32_t seed, HostRecord* rec) {
  const VolumeView<float> vol = MakeView(level.shape, level.geometry, x.data());
  const TrainingRays<float> rays = RaysOf(level);
  for (int64_t i = 0; i < rays.count; ++i) {
    if (!rec->view.Records(i)) continue;
    const TrainingRay r = RayOf(rays, vol, level.geometry.box, i, seed, level.residuals.jitter,
                                level.residuals.pixel_jitter);
    float target[3];
    TargetOf(rays, i, target);
    const RayOutput<float> fwd = Forward(vol, r.ray, r.jit, target, OpacityResidualWeight(level),
                                         level.residuals.stop_transmittance, nullptr, AlphaOf(rays, i),
                                         TransformOfRay(rays, vol, i));
    const float scale = RobustRowScale(fwd.residual, level.residuals.robust_scale);
    const int64_t first = ReserveInOrder(rec->view, EntriesToReserve(fwd));
    RecordWriter w;
    w.Begin(rec->view, first);
    RecordOnlyVisitor v{w};
    if (r.pose >= 0) {
      GeometryVisitor<float> geometry(vol, r.ray, r.jit);
      BothVisitors<RecordOnlyVisitor, GeometryVisitor<float>> both{v, geometry};
      Backward(vol, r.ray, r.jit, fwd, both);
      const PoseRow<float> row = PoseRowOf(vol, vol.params + r.pose, r.forward, r.ray, geometry.grad);
      FinishRecord(rec->view, i, first, w, fwd, scale, &row);
    } else {
      Backward(vol, r.ray, r.jit, fwd, v);
      FinishRecord(rec->view, i, first, w, fwd, scale, nullptr);
    }
    if (first >= 0) {
      EXPECT_LE(w.at, EntriesToReserve(fwd));
    }
  }
}

// J^T J p over the recorded rays, as JtJpRecordKernel computes it; *recorded: how many were.
std::vector<float> Product(const LevelProblem& level, const std::vector<float>& x, uint32_t seed,
                           const HostRecord& rec, const std::vector<float>& p, const float* free,
                           int64_t* recorded = nullptr, int64_t* samples = nullptr) {
  const VolumeView<float> vol = MakeView(level.shape, level.geometry, x.data());
  const TrainingRays<float> rays = RaysOf(level);
  std::vector<float> out(p.size(), 0.f);
  HostSink sink{&out};
  int64_t n = 0, used = 0;
  for (int64_t i = 0; i < rays.count; ++i) {
    if (!rec.view.Records(i) || rec.heads[rec.view.Slot(i)].first < 0) continue;
    const TrainingRay r = RayOf(rays, vol, level.geometry.box, i, seed, level.residuals.jitter,
                                level.residuals.pixel_jitter);
    const RayExposure<float> e =
        RecordedExposure(rec.view, i, vol.ExposureStart(), ExposureSlotOf(rays, i), TransformOfRay(rays, vol, i));
    used += RecordedJtJp(rec.view, i, vol, r, e, p.data(), free, sink, sink, sink);
    ++n;
  }
  if (recorded) *recorded = n;
  if (samples) *samples = used;
  return out;
}

enum : VecId { kX, kG, kD, kP, kOut, kVectors };

// The CPU backend's J^T J p on the rays of jtj, with its record of `kind` (compact or exact),
// optionally restricted to `free` (RestrictJacobian).
std::vector<float> CpuProduct(const LevelProblem& level, const std::vector<float>& x, uint32_t seed, RaySubset jtj,
                              const std::vector<float>& p, bool compact, const std::vector<float>* free,
                              int64_t* samples) {
  CpuBackendOptions o;
  o.threads = 2;
  o.compact_jacobian = compact;
  o.merged_jacobian = false;
  auto b = MakeCpuBackend(o);
  b->SetLevel(level, kVectors);
  b->Upload(kX, x);
  b->Upload(kP, p);
  b->Linearize(kX, seed, kG, kD, RaySubset{}, jtj);
  if (free) {
    b->Upload(kG, *free);
    b->RestrictJacobian(kG);
  }
  *samples = b->MultiplyJtJ(kP, kOut).samples;
  std::vector<float> out(p.size());
  b->Download(kOut, out);
  return out;
}

std::vector<float> Masked(std::vector<float> v, const std::vector<float>& free) {
  for (size_t i = 0; i < v.size(); ++i) v[i] *= free[i];
  return v;
}

// Every case against the CPU's compact and exact records, on every parameter and with the first
// half of the cells' densities held (their cells emptied, p 0 there: what RestrictJacobian lets a
// backend drop; outputs compared on the free entries, the only ones the solver keeps).
void ExpectTheCpuRecords(const LevelProblem& level, const std::vector<float>& x, RaySubset jtj, const char* what) {
  SCOPED_TRACE(what);
  const uint32_t seed = 11;
  const std::vector<float> pv = test::RandomDirection(level.shape, 4);
  HostRecord rec(level, int64_t{1} << 20, jtj);
  Record(level, x, seed, &rec);
  int64_t recorded = 0, samples = 0, cpu_samples = 0, exact_samples = 0;
  const std::vector<float> got = Product(level, x, seed, rec, pv, nullptr, &recorded, &samples);
  EXPECT_EQ(recorded, RaySubset(jtj).CountIn(0, level.rays->size()));
  const std::vector<float> compact = CpuProduct(level, x, seed, jtj, pv, true, nullptr, &cpu_samples);
  const std::vector<float> exact = CpuProduct(level, x, seed, jtj, pv, false, nullptr, &exact_samples);
  EXPECT_EQ(samples, exact_samples);
  EXPECT_GT(samples, 100);
  // The volume's entries, and the photos' (exposures and poses) on their own scale.
  const auto photos = static_cast<std::ptrdiff_t>(level.shape.ExposureStart());
  const auto expect_close = [&](const std::vector<float>& a, const std::vector<float>& b, double tol, const char* what) {
    test::ExpectAllClose(std::vector<float>(a.begin(), a.begin() + photos),
                         std::vector<float>(b.begin(), b.begin() + photos), tol, 5 * tol, what);
    if (level.shape.exposures == 0) return;
    test::ExpectAllClose(std::vector<float>(a.begin() + photos, a.end()), std::vector<float>(b.begin() + photos, b.end()),
                         tol, 5 * tol, what);
  };
  expect_close(got, compact, 2e-6, "J^T J p against the CPU's compact record");
  expect_close(got, exact, 3e-3, "J^T J p against the CPU's exact record");
  EXPECT_NE(got, exact);  // rounded to bfloat16

  // Restricted: the cells of the first half of the stored cells hold no density and theirs is held.
  std::vector<float> x_held = x, free(x.size(), 1.f), p_held = pv;
  const int64_t cells = level.shape.StoredCells();
  for (int64_t c = 0; c < cells; ++c) {
    free[GridParam(c, 3)] = 0.f;
    p_held[GridParam(c, 3)] = 0.f;
    if (2 * c < cells) x_held[GridParam(c, 3)] = 0.f;
  }
  HostRecord held(level, int64_t{1} << 20, jtj);
  Record(level, x_held, seed, &held);
  int64_t restricted_samples = 0;
  const std::vector<float> got_r = Product(level, x_held, seed, held, p_held, free.data(), nullptr, &restricted_samples);
  const std::vector<float> compact_r = CpuProduct(level, x_held, seed, jtj, p_held, true, &free, &cpu_samples);
  EXPECT_LT(restricted_samples, samples) << "the empty, held cells' samples are skipped";
  expect_close(Masked(got_r, free), Masked(compact_r, free), 2e-6, "restricted J^T J p against the CPU's compact record");
}

TEST(RayRecordTest, DenseLevel) {
  const TinyProblem p(3, 8, 4, 4, 12, 10);
  ExpectTheCpuRecords(p.Level(), p.x, RaySubset{}, "dense");
  ExpectTheCpuRecords(p.Level(), p.x, RaySubset{3, 1}, "dense, every 3rd ray from 1");
}

TEST(RayRecordTest, SparseLevel) {
  const TinyProblem p(5, 16, 4, 4, 12, 10);
  const test::SparseVersion s(p, {1, 0, 0, 1, 0, 1, 1, 0});
  ExpectTheCpuRecords(s.level, s.x, RaySubset{}, "sparse bricks");
}

TEST(RayRecordTest, SphericalHarmonicsExposuresPosesAndTheRobustLoss) {
  TinyProblem sh(7, 8, 4, 4, 12, 10);
  sh.AddSh(1, 8);
  ExpectTheCpuRecords(sh.Level(), sh.x, RaySubset{}, "degree 1");
  TinyProblem photos(9, 8, 4, 4, 12, 10);
  photos.AddExposures(10);
  photos.AddPoses(11);
  LevelProblem level = photos.Level();
  level.residuals.robust_scale = 0.1f;
  ExpectTheCpuRecords(level, photos.x, RaySubset{}, "exposures, poses, robust loss");
}

// The room is handed out ray by ray: each ray's entries follow the one before's reserve, and from
// the first ray that does not fit on no ray is recorded (first -1, for J^T J p to recompute), while
// the rays recorded give the same product as in a record with room for all.
TEST(RayRecordTest, RaysPastTheRoomAreLeftToRecompute) {
  const TinyProblem p(3, 8, 4, 4, 12, 10);
  const LevelProblem level = p.Level();
  HostRecord full(level, int64_t{1} << 20, RaySubset{});
  Record(level, p.x, 11, &full);
  const auto needed = static_cast<int64_t>(full.used);
  HostRecord half(level, needed / 2, RaySubset{});
  Record(level, p.x, 11, &half);
  EXPECT_EQ(static_cast<int64_t>(half.used), needed) << "every ray asks; the counter passes the room";
  int64_t recorded = 0, next = 0;
  bool ran_out = false;
  for (int64_t i = 0; i < level.rays->size(); ++i) {
    const RayRecordHead& h = half.heads[i];
    if (h.first < 0) {
      ran_out = true;
      EXPECT_EQ(h.count, 0u);
      continue;
    }
    EXPECT_FALSE(ran_out) << "ray " << i << " recorded after one that did not fit";
    EXPECT_EQ(h.first, next);
    EXPECT_LE(h.first + h.count, needed / 2);
    EXPECT_EQ(h.count, full.heads[i].count);
    next = full.heads[i + 1].first;
    ++recorded;
  }
  EXPECT_TRUE(ran_out);
  EXPECT_GT(recorded, 0);
  // The recorded rays' product equals the full record's on those rays.
  HostRecord prefix(level, int64_t{1} << 20, RaySubset{});
  Record(level, p.x, 11, &prefix);
  for (int64_t i = recorded; i < level.rays->size(); ++i) prefix.heads[i].first = -1;
  const std::vector<float> pv = test::RandomDirection(level.shape, 4);
  int64_t n = 0;
  EXPECT_EQ(Product(level, p.x, 11, half, pv, nullptr, &n), Product(level, p.x, 11, prefix, pv, nullptr));
  EXPECT_EQ(n, recorded);
}

// The plan (device_record_plan.h) sizes the record from every 16th ray's march: an upper bound of
// what Linearize's rays ask for (here a dense level marched to its end: a bound within 40 % of
// it), all of it where the room allows, as much as fits where not (the estimate then says what
// a whole record would take), none below an eighth; on every 3rd ray, a third.
TEST(RayRecordTest, ThePlanBoundsWhatTheRaysAskFor) {
  const TinyProblem p(3, 8, 4, 4, 12, 10);
  LevelProblem level = p.Level();
  HostRecord rec(level, int64_t{1} << 20, RaySubset{});
  Record(level, p.x, 11, &rec);
  const auto asked = static_cast<int64_t>(rec.used);
  const DeviceRecordPlan all = PlanDeviceRecord(level, int64_t{1} << 40);
  EXPECT_EQ(all.slots, level.rays->size());
  EXPECT_EQ(all.slot_bytes, static_cast<int64_t>(sizeof(RayRecordHead)));
  EXPECT_GE(all.wanted, asked);
  EXPECT_LT(all.wanted, asked * 14 / 10);
  EXPECT_EQ(all.capacity, all.wanted);
  EXPECT_FALSE(all.Partial());
  EXPECT_EQ(all.Bytes(), all.wanted * 9 + all.slots * 32);

  const int64_t half_room = all.slots * all.slot_bytes + all.wanted / 2 * DeviceRecordPlan::kEntryBytes;
  const DeviceRecordPlan half = PlanDeviceRecord(level, half_room);
  EXPECT_TRUE(half.Partial());
  EXPECT_EQ(half.capacity, all.wanted / 2);
  EXPECT_LE(half.Bytes(), half_room);
  EXPECT_EQ(half.WantedBytes(), all.Bytes());
  const DeviceRecordPlan little = PlanDeviceRecord(level, all.slots * all.slot_bytes + all.wanted / 10 * 9);
  EXPECT_EQ(little.capacity, 0) << "under an eighth: recompute instead";
  EXPECT_EQ(little.Bytes(), 0);
  EXPECT_EQ(PlanDeviceRecord(level, -5).capacity, 0);

  // A sparse level: its stored bricks' steps; still at least what its rays ask for.
  const TinyProblem q(5, 16, 4, 4, 12, 10);
  const test::SparseVersion sparse(q, {1, 0, 0, 1, 0, 0, 0, 0});
  HostRecord sparse_rec(sparse.level, int64_t{1} << 20, RaySubset{});
  Record(sparse.level, sparse.x, 11, &sparse_rec);
  const DeviceRecordPlan sparse_plan = PlanDeviceRecord(sparse.level, int64_t{1} << 40);
  EXPECT_GE(sparse_plan.wanted, static_cast<int64_t>(sparse_rec.used));
  EXPECT_LT(sparse_plan.wanted, PlanDeviceRecord(q.Level(), int64_t{1} << 40).wanted / 2) << "fewer than the dense march";
  // With the level's start and early termination: rays end where the start turns opaque, a
  // prediction with half as much again (densities raised 30x so that rays end a few cells in).
  TinyProblem opaque(3, 16, 4, 4, 12, 10);
  const int64_t whole = PlanDeviceRecord(opaque.Level(), int64_t{1} << 40).wanted;
  for (int64_t i = 0; i < opaque.shape.ParamCount(); ++i) {
    if (KindOf(opaque.shape, i) == ParamKind::kGridDensity) opaque.x[i] *= 30.f;
  }
  LevelProblem ending = opaque.Level();
  ending.residuals.stop_transmittance = 1e-3f;
  HostRecord ending_rec(ending, int64_t{1} << 20, RaySubset{});
  Record(ending, opaque.x, 11, &ending_rec);
  ending.start = opaque.x;
  const DeviceRecordPlan seeing = PlanDeviceRecord(ending, int64_t{1} << 40);
  EXPECT_GE(seeing.wanted, static_cast<int64_t>(ending_rec.used));
  // Half as much again, and a step and a slot a ray (these rays take 2 samples each).
  EXPECT_LT(seeing.wanted, static_cast<int64_t>(ending_rec.used) * 2 + 3 * ending.rays->size());
  EXPECT_LT(seeing.wanted, whole * 3 / 4) << "the opaque start ends the rays early";

  TinyProblem photos = p;
  photos.AddExposures(4);
  photos.AddPoses(5);
  level = photos.Level();
  level.jtj_ray_stride = 3;
  const DeviceRecordPlan third = PlanDeviceRecord(level, int64_t{1} << 40);
  EXPECT_EQ(third.slots, (level.rays->size() + 2) / 3);
  EXPECT_EQ(third.slot_bytes, static_cast<int64_t>(sizeof(RayRecordHead) + 3 * sizeof(float) + 28 * sizeof(uint16_t)));
  EXPECT_NEAR(static_cast<double>(third.wanted), all.wanted / 3.0, all.wanted * 0.05);
}

}  // namespace
}  // namespace perf::recon
