#include "lab/eval/plane_map_eval.h"

#include "core/common/angles.h"
#include "core/common/plane.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace slapse {

StatusOr<PlaneMapErrors> EvaluatePlaneMap(const std::vector<PlaneEstimate>& estimates,
                                          const GroundTruth& gt, double metres_per_unit,
                                          double min_seen_s) {
  struct Acc {
    double first_s = 1e30, last_s = -1e30, sum_d = 0, sum_n = 0;
    int n = 0;
  };
  std::map<int, Acc> per_track;
  for (const PlaneEstimate& e : estimates) {
    if (e.anchor_index < 0 || e.anchor_index >= static_cast<int64_t>(gt.frames.size())) {
      return InvalidArgumentError("plane estimate at anchor " + std::to_string(e.anchor_index) +
                                  " outside the ground truth");
    }
    const GtFrame& frame = gt.frames[e.anchor_index];
    std::map<int, int> votes;
    for (int mb : e.mb_indices) {
      if (mb >= 0 && mb < static_cast<int>(frame.mb_labels.size()) && frame.mb_labels[mb] >= 0) {
        ++votes[frame.mb_labels[mb]];
      }
    }
    int best = -1, best_votes = 0;
    for (const auto& [id, v] : votes) {
      if (v > best_votes) best = id, best_votes = v;
    }
    Acc& acc = per_track[e.track_id];
    acc.first_s = std::min(acc.first_s, frame.timestamp_s);
    acc.last_s = std::max(acc.last_s, frame.timestamp_s);
    if (best < 0 || !(e.pi_cam.norm() > 0)) continue;
    // The true plane in this camera, on the camera's side.
    const GtPlane& p = gt.planes[best];
    const Plane3d true_c = PlaneInCamera(frame.world_from_cam, {p.normal_world, p.distance_m},
                                         /*facing_camera=*/true);
    const Eigen::Vector3d& n_true = true_c.normal;
    const double d_true = true_c.distance;
    const double d_est = metres_per_unit / e.pi_cam.norm();
    const double cos_angle = std::clamp(e.pi_cam.normalized().dot(n_true), -1.0, 1.0);
    acc.sum_d += std::abs(d_est - d_true);
    acc.sum_n += RadToDeg(std::acos(cos_angle));
    ++acc.n;
  }
  PlaneMapErrors out;
  for (const auto& [id, acc] : per_track) {
    if (acc.n == 0 || acc.last_s - acc.first_s < min_seen_s) continue;
    ++out.planes_evaluated;
    out.eps_d_m += acc.sum_d / acc.n;
    out.eps_n_deg += acc.sum_n / acc.n;
  }
  if (out.planes_evaluated > 0) {
    out.eps_d_m /= out.planes_evaluated;
    out.eps_n_deg /= out.planes_evaluated;
  }
  return out;
}

void AppendPlaneEstimates(int64_t anchor_index, const std::vector<PlaneTrack>& filter_planes,
                          const std::vector<ExtractedPlane>& extracted,
                          const std::vector<int>& extracted_filter_ids,
                          std::vector<PlaneEstimate>* estimates) {
  for (const PlaneTrack& track : filter_planes) {
    PlaneEstimate e{anchor_index, track.track_id, track.pi, {}};
    for (size_t i = 0; i < extracted.size() && i < extracted_filter_ids.size(); ++i) {
      if (extracted_filter_ids[i] != track.track_id) continue;
      e.mb_indices.insert(e.mb_indices.end(), extracted[i].mb_indices.begin(),
                          extracted[i].mb_indices.end());
    }
    std::sort(e.mb_indices.begin(), e.mb_indices.end());
    e.mb_indices.erase(std::unique(e.mb_indices.begin(), e.mb_indices.end()), e.mb_indices.end());
    if (!e.mb_indices.empty()) estimates->push_back(std::move(e));
  }
}

}  // namespace slapse
