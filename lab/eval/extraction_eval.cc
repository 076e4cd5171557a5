#include "lab/eval/extraction_eval.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <optional>

#include "core/common/angles.h"
#include "core/common/json_io.h"
#include "core/common/mb_grid.h"
#include "core/common/so3.h"
#include "core/common/timing.h"
#include "core/estimators/epipolar_plane.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"

namespace slapse {
namespace {

// Degrees per radian. Multiplying by it is not RadToDeg's x * 180 / pi
// bit for bit, and the per-plane CSV has always used this product, so it stays
// (its value is angles.h's: RadToDeg(1) is exactly 180 / pi).
const double kRadToDeg = RadToDeg(1.0);

// The angle between two nonzero vectors, degrees (AngleBetweenDeg but for the
// product order above).
double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return kRadToDeg * std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0));
}

// The video of a drive directory: meta.json names it; default drive.ts.
std::string VideoOf(const std::string& dir) {
  std::string video;
  if (auto meta = ReadJsonFile(dir + "/meta.json");
      meta.ok() && GetString(*meta, "video", dir + "/meta.json", &video).ok()) {
    return dir + "/" + video;
  }
  return dir + "/drive.ts";
}

// Diagnostic features of an extracted plane for the per-plane CSV (candidates
// for telling false positives from true ones; docs/PLANE_EXTRACTION.md says
// which separated nothing). "Kept" cells hold a correspondence that survived
// the plane-at-infinity threshold (including ones on other planes).
struct PlaneShapeStats {
  double mean_imvs = 0;           // mean merged MVs per correspondence
  double e_inlier_share = 0;      // share of its correspondences that are E-inliers
  double median_parallax_px = 0;  // rotation-compensated parallax
  double hole_share = 0;  // kept cells outside the set with >= 5 of 8 neighbours in it / set size
  double boundary_share = 0;    // set cells with < 8 neighbours in the set / set size
  double fill_share = 0;        // set / (set + kept cells outside it with >= 3 neighbours in it)
  double bbox_fill = 0;         // set / its bounding box of cells
  double near2 = 0, near3 = 0;  // kept points off the plane by (eps, 2 eps] / (eps, 3 eps] near it
  double back_fit = -1, back_fit15 = -1;  // share of its blocks whose previous-pair MV fits it
};

// Backward consistency: the plane moved into the previous pair's later frame
// and checked on that pair's MVs at the blocks' earlier positions. With
// X_e = R X_l + t (this pair, |t| = 1) and m_l . X_l = 1:
//   m_e = R m_l / (1 + m_l . R^T t),
// then H_prev = K (R' + t' m_e^T) K^-1 with the previous pair's motion
// (|t'| = 1: the same unit up to the change of speed, as in tracking).
void BackwardFit(const AnchorPair& pair, const InfinityResult& inf, const AnchorPair& prev,
                 const InfinityResult& prev_inf, const Intrinsics& K, const ExtractedPlane& plane,
                 double eps, PlaneShapeStats* s) {
  if (!plane.m_later || !inf.has_motion || !prev_inf.has_motion ||
      prev.later_index != pair.earlier_index)
    return;
  const Rigid3d efl = inf.later_from_earlier.Inverse();
  const Eigen::Matrix3d R = efl.R();
  const Eigen::Vector3d& m_l = *plane.m_later;
  const double den = 1.0 + m_l.dot(R.transpose() * efl.translation);
  if (den <= 0) return;
  const Eigen::Vector3d m_e = R * m_l / den;
  const Eigen::Matrix3d H =
      EpipolarPlaneEstimator::Homography(m_e, K, prev_inf.later_from_earlier.Inverse());
  std::vector<int> at_cell(prev.mb_cols * prev.mb_rows, -1);
  for (size_t i = 0; i < prev.correspondences.size(); ++i)
    at_cell[prev.correspondences[i].mb_index] = static_cast<int>(i);
  int n = 0, fit = 0, fit15 = 0;
  for (int i : plane.correspondence_indices) {
    const Eigen::Vector2d& x = pair.correspondences[i].x_earlier_px;
    const int col = MbCellOf(x.x()), row = MbCellOf(x.y());
    if (col < 0 || row < 0 || col >= prev.mb_cols || row >= prev.mb_rows) continue;
    const int j = at_cell[row * prev.mb_cols + col];
    if (j < 0) continue;
    const Correspondence& c = prev.correspondences[j];
    const Eigen::Vector3d p = H * c.x_later_px.homogeneous();
    if (p.z() <= 0) continue;
    const double r = (c.x_earlier_px - p.hnormalized()).norm();
    ++n;
    fit += r <= eps;
    fit15 += r <= 1.5 * eps;
  }
  if (n > 0) {
    s->back_fit = static_cast<double>(fit) / n;
    s->back_fit15 = static_cast<double>(fit15) / n;
  }
}

PlaneShapeStats ComputePlaneShapeStats(const AnchorPair& pair, const InfinityResult& inf,
                                       const ExtractedPlane& plane, double eps) {
  PlaneShapeStats s;
  const int cols = pair.mb_cols, rows = pair.mb_rows;
  std::vector<char> in_set(cols * rows, 0), kept(cols * rows, 0);
  for (int i : inf.kept_indices) kept[pair.correspondences[i].mb_index] = 1;
  std::vector<double> parallax;
  int e_in = 0;
  for (int i : plane.correspondence_indices) {
    const Correspondence& c = pair.correspondences[i];
    in_set[c.mb_index] = 1;
    s.mean_imvs += c.n_direct + c.n_indirect;
    if (!inf.e_inlier_mask.empty()) e_in += inf.e_inlier_mask[i];
    parallax.push_back(inf.parallax_px[i]);
  }
  const double n = std::max<size_t>(1, plane.correspondence_indices.size());
  s.mean_imvs /= n;
  s.e_inlier_share = e_in / n;
  if (!parallax.empty()) {
    std::nth_element(parallax.begin(), parallax.begin() + parallax.size() / 2, parallax.end());
    s.median_parallax_px = parallax[parallax.size() / 2];
  }
  auto neighbours = [&](int cell) {
    int k = 0;
    const int c0 = cell % cols, r0 = cell / cols;
    for (int r = r0 - 1; r <= r0 + 1; ++r)
      for (int c = c0 - 1; c <= c0 + 1; ++c)
        if ((r != r0 || c != c0) && r >= 0 && r < rows && c >= 0 && c < cols)
          k += in_set[r * cols + c];
    return k;
  };
  int set = 0, holes = 0, ring = 0, boundary = 0;
  int cmin = cols, cmax = -1, rmin = rows, rmax = -1;
  for (int cell = 0; cell < cols * rows; ++cell) {
    const int k = neighbours(cell);
    if (in_set[cell]) {
      ++set;
      boundary += k < 8;
      cmin = std::min(cmin, cell % cols), cmax = std::max(cmax, cell % cols);
      rmin = std::min(rmin, cell / cols), rmax = std::max(rmax, cell / cols);
    } else if (kept[cell]) {
      holes += k >= 5;
      ring += k >= 3;
    }
  }
  s.hole_share = static_cast<double>(holes) / std::max(1, set);
  s.boundary_share = static_cast<double>(boundary) / std::max(1, set);
  s.fill_share = static_cast<double>(set) / std::max(1, set + ring);
  std::vector<char> in_plane(pair.correspondences.size(), 0);
  for (int i : plane.correspondence_indices) in_plane[i] = 1;
  for (int i : inf.kept_indices) {
    const Correspondence& c = pair.correspondences[i];
    if (in_plane[i] || neighbours(c.mb_index) == 0) continue;
    const double r =
        (c.x_earlier_px - (plane.H_earlier_from_later * c.x_later_px.homogeneous()).hnormalized())
            .norm();
    s.near2 += r > eps && r <= 2 * eps;
    s.near3 += r > eps && r <= 3 * eps;
  }
  s.near2 /= std::max(1, set);
  s.near3 /= std::max(1, set);
  s.bbox_fill = set > 0 ? static_cast<double>(set) / ((cmax - cmin + 1) * (rmax - rmin + 1)) : 0;
  return s;
}

}  // namespace

void ExtractionStats::Add(const ExtractionStats& o) {
  pairs += o.pairs;
  planes += o.planes;
  true_positives += o.true_positives;
  visible += o.visible;
  visible_near += o.visible_near;
  found += o.found;
  found_near += o.found_near;
  visible_kept += o.visible_kept;
  found_kept += o.found_kept;
  merge_ms += o.merge_ms;
  threshold_ms += o.threshold_ms;
  fit_ms += o.fit_ms;
}

StatusOr<ExtractionStats> EvaluateExtraction(const std::string& drive_dir,
                                             const ExtractionEvalOptions& options) {
  auto gt = LoadGroundTruth(drive_dir);
  if (!gt.ok()) return gt.status();
  auto reader = MvReader::Open(VideoOf(drive_dir));
  if (!reader.ok()) return reader.status();
  // The pipeline's front end (merge, motion with its prior, threshold,
  // extraction); a failed motion or extraction ends the evaluation.
  FrontEnd front_end(gt->intrinsics, (*reader)->info().mv_sigma_px(),
                     {options.merge, options.infinity, options.extraction});
  ExtractionStats stats;
  std::optional<AnchorPair> prev_pair;
  std::optional<InfinityResult> prev_inf;
  FrameRecord frame;
  Status s;
  while ((s = (*reader)->Next(&frame)).ok()) {
    if (frame.index >= static_cast<int64_t>(gt->frames.size())) {
      return FailedPreconditionError("the video has more frames than its ground truth");
    }
    std::optional<FrontEndStep> step = front_end.Push(frame);
    if (!step.has_value()) continue;
    stats.merge_ms += step->times.merge_ms;
    stats.threshold_ms += step->times.threshold_ms;
    if (!step->infinity.ok()) return step->infinity.status();
    stats.fit_ms += step->times.fit_ms;
    if (!step->extraction.ok()) return step->extraction.status();
    const AnchorPair* pair = &step->pair;
    const InfinityResult* inf = &*step->infinity;
    const PlaneExtractionResult* extraction = &*step->extraction;
    const PairPlaneEvaluation ev = EvaluatePlanes(*pair, extraction->planes, *gt, options.truth);
    if (options.planes_csv != nullptr) {
      // The pair's estimated motion against the truth: rotation error and the
      // angle between the translation directions (-1 without a motion).
      double rot_err_deg = -1, dir_err_deg = -1;
      if (inf->has_motion) {
        const Rigid3d true_lfe = gt->frames[pair->later_index].world_from_cam.Inverse() *
                                 gt->frames[pair->earlier_index].world_from_cam;
        rot_err_deg =
            kRadToDeg * LogSO3(inf->later_from_earlier.R() * true_lfe.R().transpose()).norm();
        dir_err_deg = AngleDeg(inf->later_from_earlier.translation, true_lfe.translation);
      }
      // The extractor's learnt vertical against the true one (later camera frame).
      const Eigen::Vector3d true_down =
          gt->frames[pair->later_index].world_from_cam.R().transpose() * Eigen::Vector3d(0, 0, -1);
      const double vertical_err_deg = AngleDeg(front_end.vertical_down(), true_down);
      for (size_t k = 0; k < ev.matches.size(); ++k) {
        const PlaneMatch& m = ev.matches[k];
        const ExtractedPlane& p = extraction->planes[k];
        double mean_row = 0;
        for (int mb : p.mb_indices) mean_row += mb / pair->mb_cols;
        mean_row /= std::max<size_t>(1, p.mb_indices.size());
        PlaneShapeStats shape = ComputePlaneShapeStats(*pair, *inf, p, options.extraction.eps_h_px);
        if (prev_pair)
          BackwardFit(*pair, *inf, *prev_pair, *prev_inf, gt->intrinsics, p,
                      options.extraction.eps_h_px, &shape);
        std::fprintf(
            options.planes_csv,
            "%s,%lld,%d,%d,%zu,%.1f,%d,%s,%.3f,%.3f,%.3f,%d,%.3f,%.3f,"
            "%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.4f,%.3f,%.3f,%.4f,"
            "%.4f\n",
            drive_dir.c_str(), static_cast<long long>(pair->later_index), m.track_id,
            p.tracked ? 1 : 0, p.mb_indices.size(), mean_row, m.gt_plane,
            m.gt_plane >= 0 ? PlaneKindName(gt->planes[m.gt_plane].kind) : "none", m.purity,
            m.mixed_share, m.transfer_px, m.true_positive ? 1 : 0, p.rms_transfer_px,
            p.track_change, shape.mean_imvs, shape.e_inlier_share, shape.median_parallax_px,
            shape.hole_share, shape.boundary_share, shape.fill_share, shape.bbox_fill, shape.near2,
            shape.near3, shape.back_fit, shape.back_fit15,
            p.m_later ? std::abs(p.m_later->y()) / p.m_later->norm() : -1.0, rot_err_deg,
            dir_err_deg, vertical_err_deg,
            p.m_later ? std::abs(p.m_later->dot(true_down)) / p.m_later->norm() : -1.0,
            p.m_later ? std::abs(p.m_later->dot(front_end.vertical_down())) / p.m_later->norm()
                      : -1.0);
      }
    }
    prev_pair = *pair;
    prev_inf = *inf;
    ++stats.pairs;
    stats.planes += static_cast<int>(ev.matches.size());
    for (const PlaneMatch& m : ev.matches) stats.true_positives += m.true_positive;
    stats.visible += static_cast<int>(ev.visible.size());
    stats.visible_near += static_cast<int>(ev.visible_near.size());
    stats.found += static_cast<int>(ev.found.size());
    for (int id : ev.found) stats.found_near += ev.visible_near.count(id);
    std::map<int, int> kept_on;  // true plane -> kept correspondences on its blocks
    for (int i : inf->kept_indices) {
      const int label = gt->frames[pair->later_index].mb_labels[pair->correspondences[i].mb_index];
      if (label >= 0) ++kept_on[label];
    }
    for (const auto& [id, n] : kept_on) {
      if (n < options.truth.min_visible_mbs || ev.visible.count(id) == 0) continue;
      ++stats.visible_kept;
      stats.found_kept += ev.found.count(id);
    }
  }
  if (s.code() != StatusCode::kOutOfRange) return s;
  return stats;
}

}  // namespace slapse
