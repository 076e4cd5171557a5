// Accuracy of the filter's planes against the simulator's ground truth (paper
// Sec. VII): planes seen for at least `min_seen_s`; per anchor where a plane
// was held and extracted, its depth error |d - d^| (metres, in that camera)
// and normal error (degrees); eps_d and eps_n average per plane, then over
// planes.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/common/status.h"
#include "core/ekf/plane_ekf.h"
#include "core/planes/plane_extraction.h"
#include "lab/gt/ground_truth.h"

namespace slapse {

// One plane estimate at one anchor, with the macroblocks it was extracted on.
struct PlaneEstimate {
  int64_t anchor_index = -1;
  int track_id = -1;
  Eigen::Vector3d pi_cam = Eigen::Vector3d::Zero();  // n / d in the anchor's camera
  std::vector<int> mb_indices;                       // its macroblocks at that anchor
};

// Appends the filter's planes after the anchor pair ending at `anchor_index`,
// each with the macroblocks of the extracted planes that observed it in that
// pair (extracted_filter_ids[i]: the filter track id extracted[i] observed,
// PipelineStep::extracted_filter_ids); filter planes not observed in it (no
// macroblocks) are left out.
void AppendPlaneEstimates(int64_t anchor_index, const std::vector<PlaneTrack>& filter_planes,
                          const std::vector<ExtractedPlane>& extracted,
                          const std::vector<int>& extracted_filter_ids,
                          std::vector<PlaneEstimate>* estimates);

struct PlaneMapErrors {
  int planes_evaluated = 0;  // seen >= min_seen_s and associated with a true plane
  double eps_d_m = 0.0;      // mean |d - d^|
  double eps_n_deg = 0.0;    // mean angle between n and n^
};

// `metres_per_unit` scales the estimate's lengths (e.g. the first-step scale
// of EvaluateTrajectory). A plane estimate is associated with the true plane
// that most of its macroblocks see.
StatusOr<PlaneMapErrors> EvaluatePlaneMap(const std::vector<PlaneEstimate>& estimates,
                                          const GroundTruth& gt, double metres_per_unit,
                                          double min_seen_s = 0.5);

}  // namespace slapse
