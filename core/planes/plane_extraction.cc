#include "core/planes/plane_extraction.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/estimators/homography.h"
#include "core/estimators/ransac.h"

namespace slapse {
namespace {

constexpr double kMbSizePx = 16.0;

// SplitMix64 finaliser: decorrelates the seeds of consecutive RANSAC calls.
uint64_t MixSeed(uint64_t seed, uint64_t call) {
  uint64_t z = seed + 0x9E3779B97F4A7C15ull * (call + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Row-major index of the MB cell containing pixel position p, or -1 outside the
// grid. Pixel centres are on integers, so cell c spans [16c - 0.5, 16c + 15.5).
int MbCellOf(const Eigen::Vector2d& p, int mb_cols, int mb_rows) {
  const double col = std::floor((p.x() + 0.5) / kMbSizePx);
  const double row = std::floor((p.y() + 0.5) / kMbSizePx);
  if (!(col >= 0 && col < mb_cols && row >= 0 && row < mb_rows)) return -1;
  return static_cast<int>(row) * mb_cols + static_cast<int>(col);
}

}  // namespace

PlaneExtractor::PlaneExtractor(PlaneExtractionOptions options) : options_(std::move(options)) {}

void PlaneExtractor::Reset() {
  tracks_.clear();
  has_previous_ = false;
  last_later_index_ = -1;
}

StatusOr<PlaneExtractionResult> PlaneExtractor::Process(const AnchorPair& pair,
                                                        const std::vector<int>& kept_indices) {
  const auto& corr = pair.correspondences;
  const int num_corr = static_cast<int>(corr.size());
  if (pair.mb_cols <= 0 || pair.mb_rows <= 0) {
    return InvalidArgumentError("PlaneExtractor: the pair has an empty MB grid");
  }
  const int num_mbs = pair.mb_cols * pair.mb_rows;
  std::vector<int> remaining = kept_indices;
  std::sort(remaining.begin(), remaining.end());
  remaining.erase(std::unique(remaining.begin(), remaining.end()), remaining.end());
  for (int i : remaining) {
    if (i < 0 || i >= num_corr) {
      return InvalidArgumentError("PlaneExtractor: kept index " + std::to_string(i) +
                                  " out of range");
    }
    if (corr[i].mb_index < 0 || corr[i].mb_index >= num_mbs) {
      return InvalidArgumentError("PlaneExtractor: correspondence " + std::to_string(i) +
                                  " has mb_index outside the MB grid");
    }
    if (!corr[i].x_later_px.allFinite() || !corr[i].x_earlier_px.allFinite()) {
      return InvalidArgumentError("PlaneExtractor: correspondence " + std::to_string(i) +
                                  " has non-finite coordinates");
    }
  }

  RansacOptions ransac_options;
  ransac_options.max_error = options_.eps_h_px;
  ransac_options.confidence = options_.confidence;
  ransac_options.min_num_trials = options_.min_trials_per_plane;
  ransac_options.max_num_trials = options_.max_trials_per_plane;
  uint64_t ransac_call = 0;

  std::vector<Eigen::Vector2d> x_later, x_earlier;  // of `remaining`
  // Runs RANSAC over `remaining` (local indices in `subset`).
  auto run_ransac = [&](const std::vector<int>* subset) {
    x_later.resize(remaining.size());
    x_earlier.resize(remaining.size());
    for (size_t j = 0; j < remaining.size(); ++j) {
      x_later[j] = corr[remaining[j]].x_later_px;
      x_earlier[j] = corr[remaining[j]].x_earlier_px;
    }
    ransac_options.seed = MixSeed(options_.seed, ransac_call++);
    return Ransac<HomographyEstimator>(ransac_options).Estimate(x_later, x_earlier, subset);
  };
  // Builds the plane from a successful report over `remaining`.
  auto make_plane = [&](const RansacReport<Eigen::Matrix3d>& report, int track_id, bool tracked) {
    ExtractedPlane plane;
    plane.track_id = track_id;
    plane.tracked = tracked;
    plane.H_earlier_from_later = report.model;
    for (size_t j = 0; j < remaining.size(); ++j) {
      if (!report.inlier_mask[j]) continue;
      plane.correspondence_indices.push_back(remaining[j]);
      plane.mb_indices.push_back(corr[remaining[j]].mb_index);
    }
    std::sort(plane.mb_indices.begin(), plane.mb_indices.end());
    plane.mb_indices.erase(std::unique(plane.mb_indices.begin(), plane.mb_indices.end()),
                           plane.mb_indices.end());
    return plane;
  };
  auto remove_inliers = [&](const RansacReport<Eigen::Matrix3d>& report) {
    std::vector<int> rest;
    for (size_t j = 0; j < remaining.size(); ++j) {
      if (!report.inlier_mask[j]) rest.push_back(remaining[j]);
    }
    remaining.swap(rest);
  };

  PlaneExtractionResult result;
  const int min_mbs = std::max(options_.min_mbs_per_plane, HomographyEstimator::kMinNumSamples);

  // 1. Tracking.
  const bool can_track = has_previous_ && pair.earlier_index == last_later_index_;
  if (!can_track) {
    result.num_tracks_lost = static_cast<int>(tracks_.size());
  } else {
    for (const Track& track : tracks_) {
      std::vector<int> subset;
      for (size_t j = 0; j < remaining.size(); ++j) {
        const int cell = MbCellOf(corr[remaining[j]].x_earlier_px, pair.mb_cols, pair.mb_rows);
        if (cell >= 0 && track.mb_cells.count(cell)) subset.push_back(static_cast<int>(j));
      }
      if (static_cast<int>(result.planes.size()) >= options_.max_planes ||
          static_cast<int>(subset.size()) < HomographyEstimator::kMinNumSamples) {
        ++result.num_tracks_lost;
        continue;
      }
      const RansacReport<Eigen::Matrix3d> report = run_ransac(&subset);
      if (!report.success) {
        ++result.num_tracks_lost;
        continue;
      }
      int subset_inliers = 0;
      for (int j : subset) subset_inliers += report.inlier_mask[j] ? 1 : 0;
      ExtractedPlane plane = make_plane(report, track.track_id, /*tracked=*/true);
      plane.track_subset_size = static_cast<int>(subset.size());
      plane.track_subset_inliers = subset_inliers;
      if (static_cast<int>(plane.mb_indices.size()) < min_mbs ||
          subset_inliers < options_.min_track_overlap * static_cast<double>(subset.size())) {
        ++result.num_tracks_lost;
        continue;
      }
      result.planes.push_back(std::move(plane));
      remove_inliers(report);
    }
  }

  // 2. Discovery of new planes.
  while (static_cast<int>(result.planes.size()) < options_.max_planes &&
         static_cast<int>(remaining.size()) >= HomographyEstimator::kMinNumSamples) {
    const RansacReport<Eigen::Matrix3d> report = run_ransac(nullptr);
    if (!report.success) break;
    ExtractedPlane plane = make_plane(report, next_track_id_, /*tracked=*/false);
    if (static_cast<int>(plane.mb_indices.size()) < min_mbs) break;
    ++next_track_id_;
    result.planes.push_back(std::move(plane));
    remove_inliers(report);
  }
  result.unassigned_indices = remaining;

  // 3. Remember the planes' MB cells in this pair's later anchor.
  tracks_.clear();
  for (const ExtractedPlane& plane : result.planes) {
    tracks_.push_back(
        {plane.track_id, std::set<int>(plane.mb_indices.begin(), plane.mb_indices.end())});
  }
  has_previous_ = true;
  last_later_index_ = pair.later_index;
  return result;
}

}  // namespace slapse
