// motion_accuracy: per anchor pair, the rotation and translation-direction
// errors of the pair's motion (core/estimators/pair_motion.h) against a
// simulated drive's ground truth, for the full robust fit (no prior) and the
// seeded fast path (the previous pair's motion as prior: the pipeline's front
// end, core/pipeline/front_end.h, as `slapse run` computes it).
//   build/bench/motion_accuracy DRIVE_DIR [DRIVE_DIR ...]
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "core/common/angles.h"
#include "core/estimators/pair_motion.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"
#include "lab/gt/ground_truth.h"

namespace {

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return slapse::RadToDeg(Eigen::AngleAxisd(a.transpose() * b).angle());
}

struct Acc {
  int n = 0, motion = 0, from_prior = 0;
  double sq_rot = 0, sq_dir = 0;
  void Add(const slapse::PairMotionReport& r, const slapse::Rigid3d& truth) {
    ++n;
    if (!r.has_motion) return;
    ++motion;
    from_prior += r.motion_from_prior;
    const double er = AngleDeg(r.later_from_earlier.R(), truth.R());
    const double et = slapse::AngleBetweenDeg(r.later_from_earlier.translation, truth.translation);
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
    slapse::FrontEnd front_end(gt->intrinsics, (*reader)->info().mv_sigma_px());
    const slapse::InfinityOptions options;
    Acc full, seeded;
    slapse::FrameRecord frame;
    while ((*reader)->Next(&frame).ok()) {
      std::optional<slapse::FrontEndStep> step = front_end.Push(frame);
      if (!step.has_value()) continue;
      const slapse::AnchorPair& pair = step->pair;
      const slapse::Rigid3d truth = gt->frames[pair.later_index].world_from_cam.Inverse() *
                                    gt->frames[pair.earlier_index].world_from_cam;
      // The full fit: no prior.
      auto f = slapse::EstimatePairMotion(pair.correspondences, gt->intrinsics, options,
                                          options.tau_inf_px);
      const auto& s = step->infinity;
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
