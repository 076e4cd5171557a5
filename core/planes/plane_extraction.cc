#include "core/planes/plane_extraction.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "core/common/angles.h"
#include "core/common/mb_grid.h"
#include "core/common/road.h"
#include "core/estimators/epipolar_plane.h"
#include "core/estimators/homography.h"
#include "core/estimators/ransac.h"

namespace slapse {
namespace {

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

// Row-major index of the MB cell (core/common/mb_grid.h) containing pixel
// position p, or -1 outside the mb_cols x mb_rows grid.
int GridCellOf(const Eigen::Vector2d& p, int mb_cols, int mb_rows) {
  const MbCell cell = MbCellOfPixel(p);
  if (!(cell.col >= 0 && cell.col < mb_cols && cell.row >= 0 && cell.row < mb_rows)) return -1;
  return cell.row * mb_cols + cell.col;
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
  before_.reset();
  tracks_.clear();
  has_previous_ = false;
  last_later_index_ = -1;
  last_discovery_s_ = -1.0;
}

bool PlaneExtractor::Rewind() {
  if (!before_.has_value()) return false;
  tracks_ = std::move(before_->tracks);
  down_ = before_->down;
  vertical_road_blocks_ = before_->vertical_road_blocks;
  last_later_index_ = before_->last_later_index;
  has_previous_ = before_->has_previous;
  last_discovery_s_ = before_->last_discovery_s;
  before_.reset();
  return true;
}

bool PlaneExtractor::DiscoveryDue(const AnchorPair& pair,
                                  const PlaneExtractionResult& tracked) const {
  if (tracked.planes.empty() || last_discovery_s_ < 0) return true;
  const double since_s = pair.later_timestamp_s - last_discovery_s_;
  // Timestamps that went back (a restarted stream) do not postpone it. The
  // margin keeps a 0.1 s interval from missing a 10 fps pair to rounding.
  return !(since_s >= 0 && since_s < options_.min_discovery_interval_s - 1e-6);
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

// One Process call's working set: the pair, the fitter and the correspondences
// not yet on a plane (`remaining`, indices into pair.correspondences), with
// the RANSAC runs, the consensus post-processing and the plane construction
// over them.
class PlaneExtractor::PairFit {
 public:
  // A plane hypothesis over `remaining`: its model and inlier mask.
  struct Consensus {
    PlaneModel model;
    std::vector<char> mask;
  };

  PairFit(const AnchorPair& pair, const PlaneExtractionOptions& options, const PairMotion* motion,
          std::vector<int> remaining)
      : pair_(pair),
        corr_(pair.correspondences),
        options_(options),
        fitter_(MakeFitter(motion)),
        remaining_(std::move(remaining)),
        max_sq_error_(options.eps_h_px * options.eps_h_px) {
    ransac_options_.max_error = options_.eps_h_px;
    ransac_options_.confidence = options_.confidence;
    ransac_options_.min_num_trials = options_.min_trials_per_plane;
    ransac_options_.max_num_trials = options_.max_trials_per_plane;
    ransac_options_.pretest_points = options_.ransac_pretest_points;
    const int num_mbs = pair.mb_cols * pair.mb_rows;
    empty_cells_.assign(num_mbs, 1);  // MB cells without any correspondence
    for (const Correspondence& c : corr_) {
      if (c.mb_index >= 0 && c.mb_index < num_mbs) empty_cells_[c.mb_index] = 0;
    }
  }

  const std::vector<int>& remaining() const { return remaining_; }
  int MinSamples() const { return fitter_->MinSamples(); }
  const Correspondence& correspondence(int i) const { return corr_[i]; }

  // Runs RANSAC over `remaining` (local indices in `subset`); discovery (no
  // subset) samples locally when local_sampling_radius_mbs > 0. RANSAC call
  // j of the pair is seeded from (seed, j).
  RansacReport<PlaneModel> Ransac(const std::vector<int>* subset) {
    x_later_.resize(remaining_.size());
    x_earlier_.resize(remaining_.size());
    mb_of_.resize(remaining_.size());
    for (size_t j = 0; j < remaining_.size(); ++j) {
      x_later_[j] = corr_[remaining_[j]].x_later_px;
      x_earlier_[j] = corr_[remaining_[j]].x_earlier_px;
      mb_of_[j] = corr_[remaining_[j]].mb_index;
    }
    fitter_->SetPoints(x_later_, x_earlier_);
    ransac_options_.seed = MixSeed(options_.seed, ransac_call_++);
    const bool local = subset == nullptr && options_.local_sampling_radius_mbs > 0;
    if (local) {
      MbNeighbours(mb_of_, pair_.mb_cols, pair_.mb_rows, options_.local_sampling_radius_mbs,
                   &neighbours_);
    }
    return fitter_->Ransac(ransac_options_, subset, local ? &neighbours_ : nullptr);
  }

  // Connectivity split and least-squares refits of a successful report (over
  // the `remaining` of the last Ransac call; see the file comment of
  // plane_extraction.h), then the optional boundary trim.
  Consensus PostProcess(const RansacReport<PlaneModel>& report) const {
    Consensus best{report.model, LargestComponentOf(report.inlier_mask)};
    int best_count = CountSet(best.mask);
    std::vector<double> sq_residuals;
    for (int iter = 0; iter < options_.refit_iterations; ++iter) {
      PlaneModel model;
      if (!fitter_->FitMasked(best.mask, &model, &sq_residuals)) break;
      std::vector<char> mask(sq_residuals.size());
      for (size_t j = 0; j < mask.size(); ++j) mask[j] = sq_residuals[j] <= max_sq_error_ ? 1 : 0;
      mask = LargestComponentOf(mask);
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
      HomographyEstimator::Residuals(x_later_, x_earlier_, best.model.H, &sq_residuals);
      const double frac = options_.boundary_residual_frac;
      best.mask =
          TrimBoundaryCells(mb_of_, best.mask, sq_residuals, pair_.mb_cols, pair_.mb_rows,
                            frac * frac * max_sq_error_,
                            options_.boundary_ignore_empty ? empty_cells_ : std::vector<char>());
      best.mask = LargestComponent(mb_of_, best.mask, pair_.mb_cols, pair_.mb_rows,
                                   options_.connectivity_radius_mbs, empty_cells_,
                                   options_.max_empty_gap_mbs);
    }
    return best;
  }

  // The plane of a consensus over `remaining`, with its RMS transfer error.
  ExtractedPlane MakePlane(const Consensus& consensus, int track_id, bool tracked) const {
    ExtractedPlane plane;
    plane.track_id = track_id;
    plane.tracked = tracked;
    plane.H_earlier_from_later = consensus.model.H;
    plane.m_later = consensus.model.m_later;
    for (size_t j = 0; j < remaining_.size(); ++j) {
      if (!consensus.mask[j]) continue;
      plane.correspondence_indices.push_back(remaining_[j]);
      plane.mb_indices.push_back(corr_[remaining_[j]].mb_index);
    }
    std::vector<double> sq_transfer;
    std::vector<Eigen::Vector2d> plane_later, plane_earlier;
    for (int i : plane.correspondence_indices) {
      plane_later.push_back(corr_[i].x_later_px);
      plane_earlier.push_back(corr_[i].x_earlier_px);
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
  }

  // Removes the points of `mask` from `remaining` (appending them to `removed` if given).
  void RemovePoints(const std::vector<char>& mask, std::vector<int>* removed) {
    std::vector<int> rest;
    for (size_t j = 0; j < remaining_.size(); ++j) {
      if (!mask[j]) {
        rest.push_back(remaining_[j]);
      } else if (removed != nullptr) {
        removed->push_back(remaining_[j]);
      }
    }
    remaining_.swap(rest);
  }

 private:
  std::vector<char> LargestComponentOf(const std::vector<char>& mask) const {
    const std::vector<char> peeled =
        PeelSparseCells(mb_of_, mask, pair_.mb_cols, pair_.mb_rows, options_.min_mb_neighbours);
    return LargestComponent(mb_of_, peeled, pair_.mb_cols, pair_.mb_rows,
                            options_.connectivity_radius_mbs, empty_cells_,
                            options_.max_empty_gap_mbs);
  }

  const AnchorPair& pair_;
  const std::vector<Correspondence>& corr_;
  const PlaneExtractionOptions& options_;
  const std::unique_ptr<PlaneFitter> fitter_;
  std::vector<int> remaining_;
  const double max_sq_error_;
  RansacOptions ransac_options_;
  uint64_t ransac_call_ = 0;
  std::vector<char> empty_cells_;
  // Of `remaining` at the last Ransac call.
  std::vector<Eigen::Vector2d> x_later_, x_earlier_;
  std::vector<int> mb_of_;
  std::vector<std::vector<int>> neighbours_;  // for local sampling
};

StatusOr<PlaneExtractionResult> PlaneExtractor::Process(const AnchorPair& pair,
                                                        const std::vector<int>& kept_indices,
                                                        const PairMotion* motion) {
  StatusOr<std::vector<int>> remaining = ValidatedKept(pair, kept_indices);
  if (!remaining.ok()) return remaining.status();
  const PairMotion* used_motion = options_.use_motion ? motion : nullptr;
  PairFit fit(pair, options_, used_motion, std::move(*remaining));
  Memory before{
      {}, down_, vertical_road_blocks_, last_later_index_, has_previous_, last_discovery_s_};

  PlaneExtractionResult result;
  // The street-scene prior's vertical in this pair's later frame: the
  // remembered one (in the earlier frame) rotated by the pair's motion.
  if (used_motion != nullptr && pair.earlier_index == last_later_index_) {
    down_ = (used_motion->later_from_earlier.R() * down_).normalized();
  }
  // 1. Tracking.
  if (has_previous_ && pair.earlier_index == last_later_index_) {
    TrackPlanes(pair, used_motion, &fit, &result);
  } else {
    result.num_tracks_lost = static_cast<int>(tracks_.size());
  }
  // 2. Discovery of new planes.
  std::vector<int> set_aside;  // inliers of models whose largest component was too small
  if (DiscoveryDue(pair, result)) {
    DiscoverPlanes(&fit, &result, &set_aside);
    last_discovery_s_ = pair.later_timestamp_s;
  }
  result.unassigned_indices = fit.remaining();
  result.unassigned_indices.insert(result.unassigned_indices.end(), set_aside.begin(),
                                   set_aside.end());
  std::sort(result.unassigned_indices.begin(), result.unassigned_indices.end());

  LearnVertical(result);
  // 3. Remember the planes' MB cells in this pair's later anchor (and what
  // was remembered before this pair, for Rewind).
  before.tracks = std::move(tracks_);
  before_ = std::move(before);
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

StatusOr<std::vector<int>> PlaneExtractor::ValidatedKept(const AnchorPair& pair,
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
  return remaining;
}

int PlaneExtractor::MinMbs(const PairFit& fit) const {
  return std::max(options_.min_mbs_per_plane, fit.MinSamples());
}

// The street-scene prior (see the options): the road test of
// core/common/road.h against the learnt vertical, one-sided (a plane whose
// normal points up, e.g. a ceiling or a canopy's underside, is no road; up to
// this change the test took |n . down| and let them pass: no pinned output
// changed, see docs/METHOD.md "Where each rule lives").
bool PlaneExtractor::IsRoad(const ExtractedPlane& plane) const {
  return IsRoadLike(*plane.m_later, down_, options_.max_road_tilt_deg);
}

// A wall (|n . down| <= sin(facade tilt)) or the road.
bool PlaneExtractor::OrientationOk(const ExtractedPlane& plane) const {
  if (options_.max_facade_tilt_deg < 0 || options_.max_road_tilt_deg < 0) return true;
  if (!plane.m_later.has_value() || !(plane.m_later->norm() > 0)) return true;
  const double facade_tilt_deg =
      options_.max_facade_tilt_deg + std::max(0.0, options_.unlearnt_vertical_margin_deg) *
                                         kVerticalHalfBlocks /
                                         (kVerticalHalfBlocks + vertical_road_blocks_);
  return std::abs(DownComponent(*plane.m_later, down_)) <= std::sin(DegToRad(facade_tilt_deg)) ||
         IsRoad(plane);
}

// Step 1 of the file comment: each remembered plane samples from the
// correspondences on its old MB cells (this pair's earlier anchor) and scores
// on all remaining ones.
void PlaneExtractor::TrackPlanes(const AnchorPair& pair, const PairMotion* motion, PairFit* fit,
                                 PlaneExtractionResult* result) {
  for (const Track& track : tracks_) {
    std::vector<int> subset;
    for (size_t j = 0; j < fit->remaining().size(); ++j) {
      const int cell = GridCellOf(fit->correspondence(fit->remaining()[j]).x_earlier_px,
                                  pair.mb_cols, pair.mb_rows);
      if (cell >= 0 && track.mb_cells.count(cell)) subset.push_back(static_cast<int>(j));
    }
    if (static_cast<int>(result->planes.size()) >= options_.max_planes ||
        static_cast<int>(subset.size()) < fit->MinSamples()) {
      ++result->num_tracks_lost;
      continue;
    }
    const RansacReport<PlaneModel> report = fit->Ransac(&subset);
    if (!report.success) {
      ++result->num_tracks_lost;
      continue;
    }
    const PairFit::Consensus consensus = fit->PostProcess(report);
    int subset_inliers = 0;
    for (int j : subset) subset_inliers += consensus.mask[j] ? 1 : 0;
    ExtractedPlane plane = fit->MakePlane(consensus, track.track_id, /*tracked=*/true);
    plane.track_subset_size = static_cast<int>(subset.size());
    plane.track_subset_inliers = subset_inliers;
    if (track.m_later.has_value() && plane.m_later.has_value() && motion != nullptr) {
      plane.track_change = TrackChange(*track.m_later, *plane.m_later, *motion);
    }
    if (static_cast<int>(plane.mb_indices.size()) < MinMbs(*fit) ||
        subset_inliers < options_.min_track_overlap * static_cast<double>(subset.size()) ||
        plane.track_change > options_.max_track_change || !OrientationOk(plane)) {
      ++result->num_tracks_lost;
      continue;
    }
    result->planes.push_back(std::move(plane));
    fit->RemovePoints(consensus.mask, nullptr);
  }
}

// The remembered plane, m_e . X_e = 1 in this pair's earlier frame, moved
// into the later one: X_e = R X_l + t gives
//   m_l = R^T m_e / (1 - m_e . t)
// (|t| = 1 per pair: consecutive pairs span the same number of frames, so
// their units agree to within the change of speed). The change is
// |m_later - m_l| / |m_l|; -1 when the plane would pass through the camera.
double PlaneExtractor::TrackChange(const Eigen::Vector3d& m_remembered,
                                   const Eigen::Vector3d& m_later, const PairMotion& motion) {
  const Rigid3d earlier_from_later = motion.later_from_earlier.Inverse();
  const double denom = 1.0 - m_remembered.dot(earlier_from_later.translation);
  if (!(denom > 0.0)) return -1.0;
  const Eigen::Vector3d m_pred = earlier_from_later.R().transpose() * m_remembered / denom;
  return (m_later - m_pred).norm() / m_pred.norm();
}

// Step 2 of the file comment: sequential RANSAC on what remains.
void PlaneExtractor::DiscoverPlanes(PairFit* fit, PlaneExtractionResult* result,
                                    std::vector<int>* set_aside) {
  const int min_mbs = MinMbs(*fit);
  int failed_discoveries = 0;
  while (static_cast<int>(result->planes.size()) < options_.max_planes &&
         static_cast<int>(fit->remaining().size()) >= fit->MinSamples()) {
    const RansacReport<PlaneModel> report = fit->Ransac(nullptr);
    if (!report.success) break;
    const PairFit::Consensus consensus = fit->PostProcess(report);
    ExtractedPlane plane = fit->MakePlane(consensus, next_track_id_, /*tracked=*/false);
    const bool too_small = static_cast<int>(plane.mb_indices.size()) < min_mbs;
    if (too_small || !OrientationOk(plane)) {
      // Too small. Without connectivity the best model is the biggest there
      // is: stop. With it, the model's inliers may be scattered blocks; set
      // them aside and look for a compact plane among the rest. The same
      // for a plane the orientation prior rejects.
      if ((too_small && options_.connectivity_radius_mbs <= 0) || report.support < min_mbs ||
          failed_discoveries >= options_.max_failed_discoveries) {
        break;
      }
      ++failed_discoveries;
      fit->RemovePoints(report.inlier_mask, set_aside);
      continue;
    }
    failed_discoveries = 0;
    ++next_track_id_;
    result->planes.push_back(std::move(plane));
    fit->RemovePoints(consensus.mask, nullptr);
  }
}

// The road planes' normals refine the vertical (a running mean, weighted by
// blocks; a new estimate moves it by at most half), and their blocks count
// as what the vertical has learnt (OrientationOk's margin).
void PlaneExtractor::LearnVertical(const PlaneExtractionResult& result) {
  Eigen::Vector3d road_sum = Eigen::Vector3d::Zero();
  double road_blocks = 0;
  for (const ExtractedPlane& plane : result.planes) {
    if (!plane.m_later.has_value() || !(plane.m_later->norm() > 0) || !IsRoad(plane)) continue;
    const Eigen::Vector3d n = plane.m_later->normalized();
    road_sum += static_cast<double>(plane.mb_indices.size()) * (n.dot(down_) >= 0 ? n : -n);
    road_blocks += static_cast<double>(plane.mb_indices.size());
  }
  if (road_blocks > 0) {
    const double weight = road_blocks / (road_blocks + kVerticalHalfBlocks);
    down_ = ((1.0 - weight) * down_ + weight * road_sum.normalized()).normalized();
    vertical_road_blocks_ += road_blocks;
  }
}

}  // namespace slapse
