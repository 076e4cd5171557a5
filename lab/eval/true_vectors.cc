#include "lab/eval/true_vectors.h"

#include <cmath>
#include <string>

#include "lab/sim/random.h"

namespace slapse {

Status TrueVectorOptions::Check() const {
  if (!(noise_px >= 0.0) || !std::isfinite(noise_px)) {
    return InvalidArgumentError("true vectors: noise_px must be finite and >= 0, got " +
                                std::to_string(noise_px));
  }
  return Status::Ok();
}

Status ReplaceWithTrueVectors(const GroundTruth& gt, const TrueVectorOptions& options,
                              std::vector<FrameRecord>* frames, TrueVectorReport* report) {
  SLAPSE_RETURN_IF_ERROR(options.Check());
  *report = TrueVectorReport{};
  const int64_t n = static_cast<int64_t>(gt.frames.size());
  SimRandom random(options.seed);
  for (FrameRecord& frame : *frames) {
    if (frame.index < 0 || frame.index >= n) {
      return InvalidArgumentError("true vectors: frame " + std::to_string(frame.index) +
                                  " is outside the ground truth's " + std::to_string(n) +
                                  " frames");
    }
    const int f = static_cast<int>(frame.index);
    for (MotionVector& mv : frame.mvs) {
      const int64_t ref = frame.ReferenceIndex(mv);
      const int label = gt.LabelAt(f, mv.x_px, mv.y_px);
      const Eigen::Vector2d x(mv.x_px, mv.y_px);
      Eigen::Vector2d x_ref;
      if (ref < 0 || ref >= n || label < 0 ||
          !gt.TransferThroughPlane(label, f, static_cast<int>(ref), x, &x_ref)) {
        ++report->kept;
        continue;
      }
      const Eigen::Vector2d d = x_ref - x;
      // The noise sequence is fixed by the seed and the records' order.
      const double nx = random.Normal(), ny = random.Normal();
      mv.dx_px = static_cast<float>(d.x() + options.noise_px * nx);
      mv.dy_px = static_cast<float>(d.y() + options.noise_px * ny);
      ++report->replaced;
    }
  }
  return Status::Ok();
}

}  // namespace slapse
