#include "lab/eval/plane_eval.h"

#include <cmath>
#include <limits>
#include <map>

#include "core/common/plane.h"

namespace slapse {

Eigen::Matrix3d TrueHomography(const GroundTruth& gt, int plane_id, int64_t earlier,
                               int64_t later) {
  const Rigid3d& world_from_later = gt.frames[later].world_from_cam;
  const Rigid3d earlier_from_later = gt.frames[earlier].world_from_cam.Inverse() * world_from_later;
  const GtPlane& p = gt.planes[plane_id];
  const Plane3d plane_c = PlaneInCamera(world_from_later, {p.normal_world, p.distance_m},
                                        /*facing_camera=*/true);
  const Eigen::Vector3d& n_c = plane_c.normal;
  const double d_c = plane_c.distance;
  const Eigen::Matrix3d K = gt.intrinsics.K();
  // X_earlier = R X_later + t = (R + t n_c^T / d_c) X_later on the plane.
  return K * (earlier_from_later.R() + earlier_from_later.translation * n_c.transpose() / d_c) *
         K.inverse();
}

PairPlaneEvaluation EvaluatePlanes(const AnchorPair& pair,
                                   const std::vector<ExtractedPlane>& planes, const GroundTruth& gt,
                                   const PlaneTruthOptions& options) {
  PairPlaneEvaluation out;
  const GtFrame& frame = gt.frames[pair.later_index];
  const std::vector<int>& labels = frame.mb_labels;
  std::map<int, int> visible_count;
  for (int l : labels) {
    if (l >= 0) ++visible_count[l];
  }
  for (const auto& [id, count] : visible_count) {
    if (count < options.min_visible_mbs) continue;
    out.visible.insert(id);
    if (gt.planes[id].kind != PlaneKind::kBackground) out.visible_near.insert(id);
  }
  std::map<int, Eigen::Matrix3d> h_true;  // per true plane, on demand
  auto true_h = [&](int id) -> const Eigen::Matrix3d& {
    auto it = h_true.find(id);
    if (it == h_true.end()) {
      it = h_true.emplace(id, TrueHomography(gt, id, pair.earlier_index, pair.later_index)).first;
    }
    return it->second;
  };
  for (const ExtractedPlane& plane : planes) {
    PlaneMatch m;
    m.track_id = plane.track_id;
    std::map<int, int> count;
    int definite = 0, mixed = 0, consistent = 0;
    for (int i : plane.correspondence_indices) {
      const Correspondence& c = pair.correspondences[i];
      const Eigen::Vector3d x = c.x_later_px.homogeneous();
      // The true plane `id` at this block moves as the extracted homography says.
      auto moves_as_h = [&](int id) {
        return ((plane.H_earlier_from_later * x).hnormalized() - (true_h(id) * x).hnormalized())
                   .norm() <= options.max_transfer_px;
      };
      const int l = labels[c.mb_index];
      if (l == kMbMixed) {
        // A block on the seam of surfaces that all move as H (flush facades)
        // is on "the wall" like a definite block: its samples on such planes
        // reach the labelling coverage. It counts for the largest of them.
        const auto it = frame.mixed_shares.find(c.mb_index);
        double on_h = 0.0;
        int largest = -1;
        if (it != frame.mixed_shares.end()) {
          for (const MbShare& part : it->second) {
            if (part.label < 0 || !moves_as_h(part.label)) continue;
            on_h += part.share;
            if (largest < 0) largest = part.label;  // shares are sorted, largest first
          }
        }
        if (on_h < kMbLabelCoverage - 1e-6) {
          ++mixed;
          continue;
        }
        ++definite;
        ++count[largest];
        ++consistent;
        continue;
      }
      ++definite;
      ++count[l];
      if (l < 0) continue;
      consistent += moves_as_h(l);
    }
    int best = -1, best_count = 0;
    for (const auto& [l, c] : count) {
      if (l >= 0 && c > best_count) best = l, best_count = c;
    }
    m.gt_plane = best;
    m.purity = definite > 0 ? static_cast<double>(consistent) / definite : 0.0;
    const size_t total = plane.correspondence_indices.size();
    m.mixed_share = total == 0 ? 1.0 : static_cast<double>(mixed) / total;
    m.transfer_px = std::numeric_limits<double>::infinity();
    if (best >= 0) {
      double sum = 0;
      for (int i : plane.correspondence_indices) {
        const Eigen::Vector3d x = pair.correspondences[i].x_later_px.homogeneous();
        sum += ((plane.H_earlier_from_later * x).hnormalized() - (true_h(best) * x).hnormalized())
                   .norm();
      }
      if (total > 0) m.transfer_px = sum / total;
    }
    m.true_positive = best >= 0 && m.purity >= options.min_purity &&
                      m.mixed_share <= options.max_mixed_share &&
                      m.transfer_px <= options.max_transfer_px;
    if (m.true_positive) out.found.insert(best);
    out.matches.push_back(m);
  }
  return out;
}

}  // namespace slapse
