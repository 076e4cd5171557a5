#include "core/planes/plane_extraction.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "core/estimators/epipolar_plane.h"
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

// For each point j (in MB cell mb_of[j] of a mb_cols x mb_rows grid), the other
// points whose cells differ from its by at most `radius` in column and row.
void MbNeighbours(const std::vector<int>& mb_of, int mb_cols, int mb_rows, int radius,
                  std::vector<std::vector<int>>* neighbours) {
  // Points per cell, as a counting sort: cell c's are in_cell[begin[c] .. begin[c + 1]).
  std::vector<int> begin(mb_cols * mb_rows + 1, 0), in_cell(mb_of.size());
  for (int cell : mb_of) ++begin[cell + 1];
  for (size_t c = 1; c < begin.size(); ++c) begin[c] += begin[c - 1];
  std::vector<int> fill(begin.begin(), begin.end() - 1);
  for (size_t j = 0; j < mb_of.size(); ++j) in_cell[fill[mb_of[j]]++] = static_cast<int>(j);
  neighbours->resize(mb_of.size());
  for (size_t j = 0; j < mb_of.size(); ++j) {
    std::vector<int>& nb = (*neighbours)[j];
    nb.clear();
    const int c0 = mb_of[j] % mb_cols, r0 = mb_of[j] / mb_cols;
    const int c_lo = std::max(0, c0 - radius), c_hi = std::min(mb_cols - 1, c0 + radius);
    for (int r = std::max(0, r0 - radius); r <= std::min(mb_rows - 1, r0 + radius); ++r) {
      // Cells (r, c_lo .. c_hi) are consecutive, so are their points in in_cell.
      nb.insert(nb.end(), in_cell.begin() + begin[r * mb_cols + c_lo],
                in_cell.begin() + begin[r * mb_cols + c_hi + 1]);
    }
    nb.erase(std::remove(nb.begin(), nb.end(), static_cast<int>(j)), nb.end());
  }
}

// Row-major index of the MB cell containing pixel position p, or -1 outside the
// grid. Pixel centres are on integers, so cell c spans [16c - 0.5, 16c + 15.5).
int MbCellOf(const Eigen::Vector2d& p, int mb_cols, int mb_rows) {
  const double col = std::floor((p.x() + 0.5) / kMbSizePx);
  const double row = std::floor((p.y() + 0.5) / kMbSizePx);
  if (!(col >= 0 && col < mb_cols && row >= 0 && row < mb_rows)) return -1;
  return static_cast<int>(row) * mb_cols + static_cast<int>(col);
}

// The points of `mask` (one entry per point, point j in MB cell mb_of[j]) whose
// cells form the largest connected component of the mask's cells. Two cells
// are neighbours when their column and row differ by at most `radius`; a path
// may also step through up to `max_gap` consecutive cells marked in `empty`
// (cells without any motion vector, which say nothing about the surface).
// Largest by point count; ties go to the component found first (lowest cell
// index). radius <= 0: the mask unchanged.
std::vector<char> LargestComponent(const std::vector<int>& mb_of, const std::vector<char>& mask,
                                   int mb_cols, int mb_rows, int radius,
                                   const std::vector<char>& empty, int max_gap) {
  if (radius <= 0) return mask;
  const int num_cells = mb_cols * mb_rows;
  std::vector<int> points_in_cell(num_cells, 0);
  for (size_t j = 0; j < mask.size(); ++j) {
    if (mask[j]) ++points_in_cell[mb_of[j]];
  }
  std::vector<int> component(num_cells, -1);
  // Empty cells: the shortest gap they were reached with, per component.
  std::vector<int> gap(num_cells, 0), gap_component(num_cells, -1);
  std::vector<int> stack;
  int best_component = -1, best_size = 0, num_components = 0;
  for (int start = 0; start < num_cells; ++start) {
    if (points_in_cell[start] == 0 || component[start] >= 0) continue;
    const int id = num_components++;
    int size = 0;
    component[start] = id;
    stack.assign(1, start);
    while (!stack.empty()) {
      const int cell = stack.back();
      stack.pop_back();
      const bool is_gap = points_in_cell[cell] == 0;
      const int cell_gap = is_gap ? gap[cell] : 0;
      if (!is_gap) size += points_in_cell[cell];
      const int c0 = cell % mb_cols, r0 = cell / mb_cols;
      for (int r = std::max(0, r0 - radius); r <= std::min(mb_rows - 1, r0 + radius); ++r) {
        for (int c = std::max(0, c0 - radius); c <= std::min(mb_cols - 1, c0 + radius); ++c) {
          const int next = r * mb_cols + c;
          if (points_in_cell[next] > 0) {
            if (component[next] >= 0) continue;
            component[next] = id;
            stack.push_back(next);
          } else if (empty[next] && cell_gap < max_gap &&
                     (gap_component[next] != id || gap[next] > cell_gap + 1)) {
            gap_component[next] = id;
            gap[next] = cell_gap + 1;
            stack.push_back(next);
          }
        }
      }
    }
    if (size > best_size) {
      best_size = size;
      best_component = id;
    }
  }
  std::vector<char> kept(mask.size(), 0);
  for (size_t j = 0; j < mask.size(); ++j) {
    kept[j] = mask[j] && component[mb_of[j]] == best_component ? 1 : 0;
  }
  return kept;
}

// `mask` without the points whose MB cell has fewer than `min_neighbours` of
// its 8 neighbour cells in the mask (one simultaneous pass): drops isolated
// blocks and one-block-wide spurs, which are mostly blocks straddling an edge
// or stray MVs that happen to fit. min_neighbours <= 0: the mask unchanged.
std::vector<char> PeelSparseCells(const std::vector<int>& mb_of, const std::vector<char>& mask,
                                  int mb_cols, int mb_rows, int min_neighbours) {
  if (min_neighbours <= 0) return mask;
  std::vector<char> in_set(mb_cols * mb_rows, 0);
  for (size_t j = 0; j < mask.size(); ++j) {
    if (mask[j]) in_set[mb_of[j]] = 1;
  }
  std::vector<char> kept(mask.size(), 0);
  for (size_t j = 0; j < mask.size(); ++j) {
    if (!mask[j]) continue;
    const int c0 = mb_of[j] % mb_cols, r0 = mb_of[j] / mb_cols;
    int neighbours = 0;
    for (int r = std::max(0, r0 - 1); r <= std::min(mb_rows - 1, r0 + 1); ++r) {
      for (int c = std::max(0, c0 - 1); c <= std::min(mb_cols - 1, c0 + 1); ++c) {
        if ((r != r0 || c != c0) && in_set[r * mb_cols + c]) ++neighbours;
      }
    }
    kept[j] = neighbours >= min_neighbours ? 1 : 0;
  }
  return kept;
}

}  // namespace

std::vector<char> TrimBoundaryCells(const std::vector<int>& mb_of, const std::vector<char>& mask,
                                    const std::vector<double>& sq_residuals, int mb_cols,
                                    int mb_rows, double max_sq_residual,
                                    const std::vector<char>& empty) {
  std::vector<char> in_set(static_cast<size_t>(mb_cols) * mb_rows, 0);
  for (size_t j = 0; j < mask.size(); ++j) {
    if (mask[j]) in_set[mb_of[j]] = 1;
  }
  std::vector<char> kept = mask;
  for (size_t j = 0; j < mask.size(); ++j) {
    if (!mask[j] || sq_residuals[j] <= max_sq_residual) continue;
    const int c0 = mb_of[j] % mb_cols, r0 = mb_of[j] / mb_cols;
    bool interior = true;
    for (int r = std::max(0, r0 - 1); r <= std::min(mb_rows - 1, r0 + 1); ++r) {
      for (int c = std::max(0, c0 - 1); c <= std::min(mb_cols - 1, c0 + 1); ++c) {
        const int cell = r * mb_cols + c;
        interior = interior && (in_set[cell] || (!empty.empty() && empty[cell]));
      }
    }
    if (!interior) kept[j] = 0;
  }
  return kept;
}

namespace {

int CountSet(const std::vector<char>& mask) {
  return static_cast<int>(std::count(mask.begin(), mask.end(), 1));
}

// A fitted plane: its homography x_earlier ~ H x_later and, from the
// motion-constrained estimator, its m = n / d in the later camera frame.
struct PlaneModel {
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
  std::optional<Eigen::Vector3d> m_later;
};

// Plane hypotheses over a point set from either estimator.
class PlaneFitter {
 public:
  virtual ~PlaneFitter() = default;
  virtual void SetPoints(const std::vector<Eigen::Vector2d>& x_later,
                         const std::vector<Eigen::Vector2d>& x_earlier) = 0;
  // neighbours: null, or per point for local sampling (Ransac<>::Estimate).
  virtual RansacReport<PlaneModel> Ransac(
      const RansacOptions& options, const std::vector<int>* subset,
      const std::vector<std::vector<int>>* neighbours = nullptr) const = 0;
  // Least-squares fit to the points of `mask`, with the squared residuals of
  // all points; false when the points are degenerate.
  virtual bool FitMasked(const std::vector<char>& mask, PlaneModel* model,
                         std::vector<double>* sq_residuals) const = 0;
  // Minimal sample size.
  virtual int MinSamples() const = 0;
};

template <typename Estimator>
class EstimatorPlaneFitter : public PlaneFitter {
 public:
  using X_t = typename Estimator::X_t;
  using M_t = typename Estimator::M_t;
  EstimatorPlaneFitter(std::function<std::vector<X_t>(const std::vector<Eigen::Vector2d>&)> prepare,
                       std::function<PlaneModel(const M_t&)> to_plane)
      : prepare_(std::move(prepare)), to_plane_(std::move(to_plane)) {}

  void SetPoints(const std::vector<Eigen::Vector2d>& x_later,
                 const std::vector<Eigen::Vector2d>& x_earlier) override {
    X_ = prepare_(x_later);
    Y_ = x_earlier;
  }
  RansacReport<PlaneModel> Ransac(
      const RansacOptions& options, const std::vector<int>* subset,
      const std::vector<std::vector<int>>* neighbours = nullptr) const override {
    const RansacReport<M_t> report =
        slapse::Ransac<Estimator>(options).Estimate(X_, Y_, subset, neighbours);
    RansacReport<PlaneModel> out;
    out.success = report.success;
    out.num_trials = report.num_trials;
    out.support = report.support;
    out.inlier_mask = report.inlier_mask;
    if (report.success) out.model = to_plane_(report.model);
    return out;
  }
  bool FitMasked(const std::vector<char>& mask, PlaneModel* model,
                 std::vector<double>* sq_residuals) const override {
    std::vector<X_t> fit_x;
    std::vector<Eigen::Vector2d> fit_y;
    for (size_t j = 0; j < mask.size(); ++j) {
      if (!mask[j]) continue;
      fit_x.push_back(X_[j]);
      fit_y.push_back(Y_[j]);
    }
    std::vector<M_t> models;
    Estimator::Estimate(fit_x, fit_y, &models);
    if (models.empty()) return false;
    Estimator::Residuals(X_, Y_, models[0], sq_residuals);
    *model = to_plane_(models[0]);
    return true;
  }
  int MinSamples() const override { return Estimator::kMinNumSamples; }

 private:
  std::function<std::vector<X_t>(const std::vector<Eigen::Vector2d>&)> prepare_;
  std::function<PlaneModel(const M_t&)> to_plane_;
  std::vector<X_t> X_;
  std::vector<Eigen::Vector2d> Y_;
};

std::unique_ptr<PlaneFitter> MakeFitter(const PairMotion* motion) {
  if (motion == nullptr) {
    return std::make_unique<EstimatorPlaneFitter<HomographyEstimator>>(
        [](const std::vector<Eigen::Vector2d>& x) { return x; },
        [](const Eigen::Matrix3d& H) {
          return PlaneModel{H, std::nullopt};
        });
  }
  const Intrinsics intrinsics = motion->intrinsics;
  const Rigid3d earlier_from_later = motion->later_from_earlier.Inverse();
  return std::make_unique<EstimatorPlaneFitter<EpipolarPlaneEstimator>>(
      [=](const std::vector<Eigen::Vector2d>& x) {
        return EpipolarPlaneEstimator::Prepare(x, intrinsics, earlier_from_later);
      },
      [=](const Eigen::Vector3d& m) {
        return PlaneModel{EpipolarPlaneEstimator::Homography(m, intrinsics, earlier_from_later), m};
      });
}

}  // namespace

PlaneExtractor::PlaneExtractor(PlaneExtractionOptions options) : options_(std::move(options)) {}

void PlaneExtractor::Reset() {
  tracks_.clear();
  has_previous_ = false;
  last_later_index_ = -1;
}

StatusOr<PlaneExtractionResult> PlaneExtractor::Process(const AnchorPair& pair,
                                                        const InfinityResult& infinity,
                                                        const Intrinsics& intrinsics) {
  const PairMotion motion{intrinsics, infinity.later_from_earlier};
  if (options_.drop_e_outliers && infinity.has_motion &&
      infinity.e_inlier_mask.size() == pair.correspondences.size()) {
    std::vector<int> kept;
    for (int i : infinity.kept_indices) {
      if (i >= 0 && i < static_cast<int>(infinity.e_inlier_mask.size()) &&
          infinity.e_inlier_mask[i]) {
        kept.push_back(i);
      }
    }
    return Process(pair, kept, &motion);
  }
  return Process(pair, infinity.kept_indices, infinity.has_motion ? &motion : nullptr);
}

StatusOr<PlaneExtractionResult> PlaneExtractor::Process(const AnchorPair& pair,
                                                        const std::vector<int>& kept_indices,
                                                        const PairMotion* motion) {
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
  ransac_options.pretest_points = options_.ransac_pretest_points;
  uint64_t ransac_call = 0;

  const PairMotion* used_motion = options_.use_motion ? motion : nullptr;
  const std::unique_ptr<PlaneFitter> fitter = MakeFitter(used_motion);
  std::vector<Eigen::Vector2d> x_later, x_earlier;  // of `remaining`
  std::vector<int> mb_of;                           // of `remaining`
  std::vector<std::vector<int>> neighbours;         // of `remaining`, for local sampling
  // Runs RANSAC over `remaining` (local indices in `subset`); discovery
  // (no subset) samples locally when local_sampling_radius_mbs > 0.
  auto run_ransac = [&](const std::vector<int>* subset) {
    x_later.resize(remaining.size());
    x_earlier.resize(remaining.size());
    mb_of.resize(remaining.size());
    for (size_t j = 0; j < remaining.size(); ++j) {
      x_later[j] = corr[remaining[j]].x_later_px;
      x_earlier[j] = corr[remaining[j]].x_earlier_px;
      mb_of[j] = corr[remaining[j]].mb_index;
    }
    fitter->SetPoints(x_later, x_earlier);
    ransac_options.seed = MixSeed(options_.seed, ransac_call++);
    const bool local = subset == nullptr && options_.local_sampling_radius_mbs > 0;
    if (local) {
      MbNeighbours(mb_of, pair.mb_cols, pair.mb_rows, options_.local_sampling_radius_mbs,
                   &neighbours);
    }
    return fitter->Ransac(ransac_options, subset, local ? &neighbours : nullptr);
  };
  // A plane hypothesis over `remaining`: its model and inlier mask.
  struct Consensus {
    PlaneModel model;
    std::vector<char> mask;
  };
  const double max_sq_error = options_.eps_h_px * options_.eps_h_px;
  std::vector<char> empty_cells(num_mbs, 1);  // MB cells without any correspondence
  for (const Correspondence& c : corr) {
    if (c.mb_index >= 0 && c.mb_index < num_mbs) empty_cells[c.mb_index] = 0;
  }
  auto largest_component = [&](const std::vector<char>& mask) {
    const std::vector<char> peeled =
        PeelSparseCells(mb_of, mask, pair.mb_cols, pair.mb_rows, options_.min_mb_neighbours);
    return LargestComponent(mb_of, peeled, pair.mb_cols, pair.mb_rows,
                            options_.connectivity_radius_mbs, empty_cells,
                            options_.max_empty_gap_mbs);
  };
  // Connectivity split and least-squares refits of a successful report (over
  // the `remaining` of the last run_ransac call).
  auto post_process = [&](const RansacReport<PlaneModel>& report) {
    Consensus best{report.model, largest_component(report.inlier_mask)};
    int best_count = CountSet(best.mask);
    std::vector<double> sq_residuals;
    for (int iter = 0; iter < options_.refit_iterations; ++iter) {
      PlaneModel model;
      if (!fitter->FitMasked(best.mask, &model, &sq_residuals)) break;
      std::vector<char> mask(sq_residuals.size());
      for (size_t j = 0; j < mask.size(); ++j) mask[j] = sq_residuals[j] <= max_sq_error ? 1 : 0;
      mask = largest_component(mask);
      const int count = CountSet(mask);
      if (count < best_count) break;
      const bool stable = mask == best.mask;
      best = {model, std::move(mask)};
      best_count = count;
      if (stable) break;
    }
    if (options_.boundary_residual_frac >= 0.0) {
      // Edge blocks whose MVs fit only loosely: drop them, then keep the
      // largest component of the rest (without peeling again).
      HomographyEstimator::Residuals(x_later, x_earlier, best.model.H, &sq_residuals);
      const double frac = options_.boundary_residual_frac;
      best.mask = TrimBoundaryCells(
          mb_of, best.mask, sq_residuals, pair.mb_cols, pair.mb_rows, frac * frac * max_sq_error,
          options_.boundary_ignore_empty ? empty_cells : std::vector<char>());
      best.mask = LargestComponent(mb_of, best.mask, pair.mb_cols, pair.mb_rows,
                                   options_.connectivity_radius_mbs, empty_cells,
                                   options_.max_empty_gap_mbs);
    }
    return best;
  };
  // Builds the plane from a consensus over `remaining`.
  auto make_plane = [&](const Consensus& consensus, int track_id, bool tracked) {
    ExtractedPlane plane;
    plane.track_id = track_id;
    plane.tracked = tracked;
    plane.H_earlier_from_later = consensus.model.H;
    plane.m_later = consensus.model.m_later;
    for (size_t j = 0; j < remaining.size(); ++j) {
      if (!consensus.mask[j]) continue;
      plane.correspondence_indices.push_back(remaining[j]);
      plane.mb_indices.push_back(corr[remaining[j]].mb_index);
    }
    std::vector<double> sq_transfer;
    std::vector<Eigen::Vector2d> plane_later, plane_earlier;
    for (int i : plane.correspondence_indices) {
      plane_later.push_back(corr[i].x_later_px);
      plane_earlier.push_back(corr[i].x_earlier_px);
    }
    HomographyEstimator::Residuals(plane_later, plane_earlier, consensus.model.H, &sq_transfer);
    double sum_sq = 0;
    for (double r : sq_transfer) sum_sq += r;
    plane.rms_transfer_px =
        sq_transfer.empty() ? 0.0 : std::sqrt(sum_sq / static_cast<double>(sq_transfer.size()));
    std::sort(plane.mb_indices.begin(), plane.mb_indices.end());
    plane.mb_indices.erase(std::unique(plane.mb_indices.begin(), plane.mb_indices.end()),
                           plane.mb_indices.end());
    return plane;
  };
  // Removes the points of `mask` from `remaining` (appending them to `removed` if given).
  auto remove_points = [&](const std::vector<char>& mask, std::vector<int>* removed) {
    std::vector<int> rest;
    for (size_t j = 0; j < remaining.size(); ++j) {
      if (!mask[j]) {
        rest.push_back(remaining[j]);
      } else if (removed != nullptr) {
        removed->push_back(remaining[j]);
      }
    }
    remaining.swap(rest);
  };

  PlaneExtractionResult result;
  const int min_mbs = std::max(options_.min_mbs_per_plane, fitter->MinSamples());
  // The street-scene prior on a plane's orientation (see the options).
  // The vertical in this pair's later frame: the remembered one (in the
  // earlier frame) rotated by the pair's motion.
  if (used_motion != nullptr && pair.earlier_index == last_later_index_) {
    down_ = (used_motion->later_from_earlier.R() * down_).normalized();
  }
  auto down_component = [&](const ExtractedPlane& plane) {
    return std::abs(plane.m_later->dot(down_)) / plane.m_later->norm();
  };
  auto is_road = [&](const ExtractedPlane& plane) {
    return down_component(plane) >= std::cos(options_.max_road_tilt_deg * M_PI / 180.0);
  };
  auto orientation_ok = [&](const ExtractedPlane& plane) {
    if (options_.max_facade_tilt_deg < 0 || options_.max_road_tilt_deg < 0) return true;
    if (!plane.m_later.has_value() || !(plane.m_later->norm() > 0)) return true;
    const double facade_tilt_deg =
        options_.max_facade_tilt_deg +
        (vertical_learnt_ ? 0.0 : std::max(0.0, options_.unlearnt_vertical_margin_deg));
    return down_component(plane) <= std::sin(facade_tilt_deg * M_PI / 180.0) || is_road(plane);
  };

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
          static_cast<int>(subset.size()) < fitter->MinSamples()) {
        ++result.num_tracks_lost;
        continue;
      }
      const RansacReport<PlaneModel> report = run_ransac(&subset);
      if (!report.success) {
        ++result.num_tracks_lost;
        continue;
      }
      const Consensus consensus = post_process(report);
      int subset_inliers = 0;
      for (int j : subset) subset_inliers += consensus.mask[j] ? 1 : 0;
      ExtractedPlane plane = make_plane(consensus, track.track_id, /*tracked=*/true);
      plane.track_subset_size = static_cast<int>(subset.size());
      plane.track_subset_inliers = subset_inliers;
      if (track.m_later.has_value() && plane.m_later.has_value() && used_motion != nullptr) {
        // The remembered plane, m_e . X_e = 1 in this pair's earlier frame,
        // moved into the later one: X_e = R X_l + t gives
        // m_l = R^T m_e / (1 - m_e . t) (|t| = 1 per pair: consecutive pairs
        // span the same number of frames, so their units agree to within the
        // change of speed).
        const Rigid3d earlier_from_later = used_motion->later_from_earlier.Inverse();
        const double denom = 1.0 - track.m_later->dot(earlier_from_later.translation);
        if (denom > 0.0) {
          const Eigen::Vector3d m_pred =
              earlier_from_later.R().transpose() * *track.m_later / denom;
          plane.track_change = (*plane.m_later - m_pred).norm() / m_pred.norm();
        }
      }
      if (static_cast<int>(plane.mb_indices.size()) < min_mbs ||
          subset_inliers < options_.min_track_overlap * static_cast<double>(subset.size()) ||
          plane.track_change > options_.max_track_change || !orientation_ok(plane)) {
        ++result.num_tracks_lost;
        continue;
      }
      result.planes.push_back(std::move(plane));
      remove_points(consensus.mask, nullptr);
    }
  }

  // 2. Discovery of new planes.
  std::vector<int> set_aside;  // inliers of models whose largest component was too small
  int failed_discoveries = 0;
  while (static_cast<int>(result.planes.size()) < options_.max_planes &&
         static_cast<int>(remaining.size()) >= fitter->MinSamples()) {
    const RansacReport<PlaneModel> report = run_ransac(nullptr);
    if (!report.success) break;
    const Consensus consensus = post_process(report);
    ExtractedPlane plane = make_plane(consensus, next_track_id_, /*tracked=*/false);
    const bool too_small = static_cast<int>(plane.mb_indices.size()) < min_mbs;
    if (too_small || !orientation_ok(plane)) {
      // Too small. Without connectivity the best model is the biggest there
      // is: stop. With it, the model's inliers may be scattered blocks; set
      // them aside and look for a compact plane among the rest. The same
      // for a plane the orientation prior rejects.
      if ((too_small && options_.connectivity_radius_mbs <= 0) || report.support < min_mbs ||
          failed_discoveries >= options_.max_failed_discoveries) {
        break;
      }
      ++failed_discoveries;
      remove_points(report.inlier_mask, &set_aside);
      continue;
    }
    failed_discoveries = 0;
    ++next_track_id_;
    result.planes.push_back(std::move(plane));
    remove_points(consensus.mask, nullptr);
  }
  result.unassigned_indices = remaining;
  result.unassigned_indices.insert(result.unassigned_indices.end(), set_aside.begin(),
                                   set_aside.end());
  std::sort(result.unassigned_indices.begin(), result.unassigned_indices.end());

  // The road planes' normals refine the vertical (a running mean, weighted
  // by blocks; a new estimate moves it by at most half).
  Eigen::Vector3d road_sum = Eigen::Vector3d::Zero();
  double road_blocks = 0;
  for (const ExtractedPlane& plane : result.planes) {
    if (!plane.m_later.has_value() || !(plane.m_later->norm() > 0) || !is_road(plane)) continue;
    const Eigen::Vector3d n = plane.m_later->normalized();
    road_sum += static_cast<double>(plane.mb_indices.size()) * (n.dot(down_) >= 0 ? n : -n);
    road_blocks += static_cast<double>(plane.mb_indices.size());
  }
  if (road_blocks > 0) {
    const double weight = road_blocks / (road_blocks + 100.0);  // 100 blocks: half way
    down_ = ((1.0 - weight) * down_ + weight * road_sum.normalized()).normalized();
    vertical_learnt_ = true;
  }

  // 3. Remember the planes' MB cells in this pair's later anchor.
  tracks_.clear();
  for (const ExtractedPlane& plane : result.planes) {
    tracks_.push_back({plane.track_id,
                       std::set<int>(plane.mb_indices.begin(), plane.mb_indices.end()),
                       plane.m_later});
  }
  has_previous_ = true;
  last_later_index_ = pair.later_index;
  return result;
}

}  // namespace slapse
