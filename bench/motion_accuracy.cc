// motion_accuracy: per anchor pair, the rotation and translation-direction
// errors of ThresholdInfinity's motion against a simulated drive's ground
// truth, for the full robust fit (no prior) and the seeded fast path (the
// previous pair's motion as prior, as the pipeline passes it).
//   build/bench/motion_accuracy DRIVE_DIR [DRIVE_DIR ...]
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "core/merge/mv_merge.h"
#include "core/mv/mv_reader.h"
#include "core/planes/infinity.h"
#include "core/sim/ground_truth.h"

namespace {

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() * 180.0 / M_PI;
}
double DirAngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::max(-1.0, std::min(1.0, a.normalized().dot(b.normalized())))) * 180.0 /
         M_PI;
}

struct Acc {
  int n = 0, motion = 0, from_prior = 0;
  double sq_rot = 0, sq_dir = 0;
  void Add(const slapse::InfinityResult& r, const slapse::Rigid3d& truth) {
    ++n;
    if (!r.has_motion) return;
    ++motion;
    from_prior += r.motion_from_prior;
    const double er = AngleDeg(r.later_from_earlier.R(), truth.R());
    const double et = DirAngleDeg(r.later_from_earlier.translation, truth.translation);
    sq_rot += er * er;
    sq_dir += et * et;
  }
  void Print(const char* name) const {
    std::printf(
        "  %-8s pairs %d, motion %d (from prior %d): rotation RMSE %.4f deg, "
        "t direction RMSE %.3f deg\n",
        name, n, motion, from_prior, std::sqrt(sq_rot / std::max(1, motion)),
        std::sqrt(sq_dir / std::max(1, motion)));
  }
};

}  // namespace

int main(int argc, char** argv) {
  Acc all_full, all_seeded;
  for (int a = 1; a < argc; ++a) {
    const std::string dir = argv[a];
    auto gt = slapse::LoadGroundTruth(dir);
    auto reader = slapse::MvReader::Open(dir + "/drive.ts");
    if (!gt.ok() || !reader.ok()) {
      std::fprintf(stderr, "cannot read %s\n", dir.c_str());
      return 1;
    }
    slapse::SegmentMerger merger(gt->intrinsics.width_px, gt->intrinsics.height_px,
                                 (*reader)->info().mv_sigma_px(), {});
    slapse::InfinityPriorTracker tracker;
    Acc full, seeded;
    slapse::FrameRecord frame;
    while ((*reader)->Next(&frame).ok()) {
      std::optional<slapse::AnchorPair> pair = merger.Push(frame);
      if (!pair.has_value()) continue;
      const slapse::Rigid3d truth = gt->frames[pair->later_index].world_from_cam.Inverse() *
                                    gt->frames[pair->earlier_index].world_from_cam;
      auto f = slapse::ThresholdInfinity(pair->correspondences, gt->intrinsics, {});
      auto s = slapse::ThresholdInfinity(pair->correspondences, gt->intrinsics, {},
                                         tracker.PriorFor(*pair));
      tracker.Record(*pair, s.ok() ? &*s : nullptr);
      if (!f.ok() || !s.ok()) continue;
      full.Add(*f, truth);
      seeded.Add(*s, truth);
      all_full.Add(*f, truth);
      all_seeded.Add(*s, truth);
    }
    std::printf("%s\n", dir.c_str());
    full.Print("full");
    seeded.Print("seeded");
  }
  std::printf("all\n");
  all_full.Print("full");
  all_seeded.Print("seeded");
  return 0;
}
