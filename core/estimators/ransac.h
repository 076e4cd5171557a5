// A generic, deterministic RANSAC (in the shape of COLMAP's) with an optional
// sampling subset, as SLAPSE's plane tracking needs (paper Sec. V-C).
//
// An Estimator provides:
//   using X_t = ...;  using Y_t = ...;  using M_t = ...;
//   static constexpr int kMinNumSamples;
//   // Fits zero or more models to the given points: a minimal sample when
//   // X.size() == kMinNumSamples, a least-squares fit when larger. Degenerate
//   // input yields no model (models->empty()).
//   static void Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
//                        std::vector<M_t>* models);
//   // One squared residual per point (may be +infinity).
//   static void Residuals(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
//                         const M_t& model, std::vector<double>* squared_residuals);
//   // Optional: a scorer that prepares the points once per Estimate / Polish
//   // call (e.g. as structure-of-arrays for vectorised arithmetic) and then
//   // gives the same squared residuals as Residuals on them.
//   class Scorer {
//    public:
//     Scorer(const std::vector<X_t>& X, const std::vector<Y_t>& Y);
//     void Residuals(const M_t& model, std::vector<double>* squared_residuals) const;
//   };
//
// Semantics of Ransac::Estimate(X, Y, sample_from):
//  - Minimal samples are drawn only from the indices in `sample_from` (all
//    points when null); every hypothesis is scored on ALL points. A point is an
//    inlier iff squared_residual <= max_error^2. Hypotheses are ranked by the
//    MSAC cost sum_i min(r_i^2, max_error^2) over all points (an inlier count
//    that also rewards small residuals).
//  - The number of trials adapts to the inlier ratio *within the sampling set*
//    (that is the set the next sample comes from):
//      N = log(1 - confidence) / log(1 - w^kMinNumSamples),
//    clamped to [min_num_trials, max_num_trials].
//  - With local_optimization (LO-RANSAC), every new so-far-best hypothesis is
//    refitted by the estimator's least-squares Estimate on its inliers at a
//    shrinking threshold (3, 2, 1.5 x max_error, then max_error until the
//    inlier set is stable, at most kMaxLocalOptimizationIterations times). A
//    refit is kept iff it lowers the MSAC cost at max_error (a pure inlier count would keep
//    a noisy minimal-sample model whenever the refit loses one borderline
//    inlier); the polished model then competes in the ranking, so hypotheses
//    are not ranked by the luck of their minimal sample's noise.
//    The reported support and mask are those of the final model.
//  - Local sampling (Estimate's `neighbours`, NAPSAC-like; null: uniform as
//    above): a sample is one pool point drawn uniformly plus kMinNumSamples - 1
//    distinct points drawn uniformly from its neighbours that are in the pool
//    (from the whole pool when it has fewer such neighbours than that, so any
//    structure can still be sampled). Structures that are spatially compact
//    (planes in an image) are then sampled whole far more often. The number
//    of trials adapts to the probability that such a sample is all-inlier
//    under the best model so far, computed exactly from its inlier mask:
//      p = (1 / |pool|) sum over pool inliers i of
//          prod_{k < kMinNumSamples - 1} (a_i - k) / (b_i - k),
//    b_i (a_i) the number of i's pool neighbours (that are inliers), or of
//    the other pool points (inliers) for an isolated i, and
//    N = log(1 - confidence) / log(1 - p), clamped as above.
//  - Pre-test (pretest_points > 0; the bail-out of Capel, BMVC 2005): most
//    hypotheses are poor, and scoring them on all points is the main cost.
//    A fixed random set of pretest_points points is drawn once per call (by
//    its own generator, so the samples are the same as without it); a
//    hypothesis goes on to full scoring only if its inliers in that set are
//    at least pretest_min_ratio x those of the best model so far (once that
//    has pretest_min_best_inliers of them). A hypothesis as good as the best
//    one fails this with small probability (binomial tails), and then only
//    that one hypothesis is lost; the trial count is unchanged.
//  - Deterministic: a fresh std::mt19937_64 seeded with `seed` per call, and an
//    own unbiased index helper (std::uniform_int_distribution's output is
//    implementation-defined, so results would differ between standard libraries).
//  - Failure (success = false, empty mask, num_trials may be > 0): X and Y sizes
//    differ, max_error <= 0, an index in sample_from is out of range, fewer than
//    kMinNumSamples distinct indices to sample from, or no hypothesis had at
//    least kMinNumSamples inliers (e.g. every sample was degenerate).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <random>
#include <type_traits>
#include <utility>
#include <vector>

namespace slapse {

struct RansacOptions {
  // Inlier threshold in the unit of the estimator's residual (not squared); > 0.
  double max_error = 0.0;
  // Probability that at least one all-inlier sample was drawn when stopping.
  double confidence = 0.999;
  int min_num_trials = 10;
  int max_num_trials = 2000;
  uint64_t seed = 0;
  // Refit on all inliers after the random search (see file comment).
  bool local_optimization = true;
  // Pre-test of hypotheses (see file comment): the size of the fixed random
  // test set; 0 (or fewer than 2x this many points) turns it off.
  int pretest_points = 0;
  // A hypothesis is scored on all points only if it has at least this
  // fraction of the best model's inliers on the test set.
  double pretest_min_ratio = 0.5;
  // ... and only once the best model has at least this many of them (fewer
  // say too little to reject anything).
  int pretest_min_best_inliers = 8;
};

template <typename Model>
struct RansacReport {
  bool success = false;
  int num_trials = 0;             // hypotheses sampled (minimal samples drawn)
  int support = 0;                // number of inliers among ALL points
  std::vector<char> inlier_mask;  // one entry per point (1 = inlier); empty on failure
  Model model{};                  // meaningful only when success
};

namespace internal {

// Uniform integer in [0, n) from a 64-bit engine, without modulo bias
// (rejection sampling on the top of the range). n > 0.
inline uint64_t UniformIndex(std::mt19937_64& rng, uint64_t n) {
  const uint64_t limit = std::numeric_limits<uint64_t>::max() -
                         std::numeric_limits<uint64_t>::max() % n;  // multiple of n
  uint64_t r;
  do {
    r = rng();
  } while (r >= limit);
  return r % n;
}

// Trials needed to draw, with probability `confidence`, one sample of
// `sample_size` inliers when a fraction `inlier_ratio` of the pool are inliers.
inline int RansacNumTrials(double inlier_ratio, int sample_size, double confidence,
                           int min_num_trials, int max_num_trials) {
  if (inlier_ratio <= 0.0) return max_num_trials;
  if (inlier_ratio >= 1.0) return min_num_trials;
  const double p_all_inliers = std::pow(inlier_ratio, sample_size);
  const double denom = std::log1p(-p_all_inliers);
  if (!(denom < 0.0)) return max_num_trials;
  const double num = std::log1p(-std::min(confidence, 1.0 - 1e-15));
  const double n = std::ceil(num / denom);
  if (!(n < static_cast<double>(max_num_trials))) return max_num_trials;
  return std::max(min_num_trials, static_cast<int>(n));
}

// The estimator's Scorer if it has one, else one that calls its Residuals.
template <typename Estimator, typename = void>
class ScorerFor {
 public:
  ScorerFor(const std::vector<typename Estimator::X_t>& X,
            const std::vector<typename Estimator::Y_t>& Y)
      : X_(X), Y_(Y) {}
  void Residuals(const typename Estimator::M_t& model,
                 std::vector<double>* squared_residuals) const {
    Estimator::Residuals(X_, Y_, model, squared_residuals);
  }

 private:
  const std::vector<typename Estimator::X_t>& X_;
  const std::vector<typename Estimator::Y_t>& Y_;
};

template <typename Estimator>
class ScorerFor<Estimator, std::void_t<typename Estimator::Scorer>> : public Estimator::Scorer {
 public:
  using Estimator::Scorer::Scorer;
};

}  // namespace internal

template <typename Estimator>
class Ransac {
 public:
  using X_t = typename Estimator::X_t;
  using Y_t = typename Estimator::Y_t;
  using M_t = typename Estimator::M_t;
  using Report = RansacReport<M_t>;

  static constexpr int kMaxLocalOptimizationIterations = 10;
  static constexpr double kLoThresholdMultipliers[] = {3.0, 2.0, 1.5};

  explicit Ransac(const RansacOptions& options) : options_(options) {}

  // neighbours: null, or one list per point (indices into X) for local
  // sampling (see the file comment).
  Report Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                  const std::vector<int>* sample_from = nullptr,
                  const std::vector<std::vector<int>>* neighbours = nullptr) const {
    Report report;
    constexpr int kSample = Estimator::kMinNumSamples;
    const int num_points = static_cast<int>(X.size());
    if (X.size() != Y.size() || !(options_.max_error > 0.0)) return report;
    std::vector<int> pool;
    if (!MakePool(num_points, sample_from, &pool)) return report;
    const int pool_size = static_cast<int>(pool.size());
    if (pool_size < kSample) return report;
    if (neighbours != nullptr && neighbours->size() != X.size()) return report;
    const std::optional<LocalNeighbours> local =
        neighbours != nullptr ? std::optional<LocalNeighbours>(
                                    MakeLocalNeighbours(pool, *neighbours, num_points))
                              : std::nullopt;

    const double max_sq_error = options_.max_error * options_.max_error;
    const int min_trials = std::max(0, options_.min_num_trials);
    const int max_trials = std::max(min_trials, options_.max_num_trials);
    const internal::ScorerFor<Estimator> scorer(X, Y);
    std::mt19937_64 rng(options_.seed);
    std::vector<X_t> sample_x(kSample);
    std::vector<Y_t> sample_y(kSample);
    std::vector<int> scratch;
    std::vector<M_t> models;
    std::vector<double> residuals, test_residuals;
    const Pretest test = MakePretest(X, Y);
    const internal::ScorerFor<Estimator> test_scorer(test.x, test.y);
    int best_test_inliers = 0;

    double best_cost = std::numeric_limits<double>::infinity();
    int best_support = 0;
    int dynamic_max_trials = max_trials;
    int trial = 0;
    for (; trial < max_trials; ++trial) {
      if (trial >= min_trials && trial >= dynamic_max_trials) break;
      DrawSample(X, Y, local ? &*local : nullptr, &rng, &pool, &scratch, &sample_x, &sample_y);
      models.clear();
      Estimator::Estimate(sample_x, sample_y, &models);
      for (const M_t& model : models) {
        if (test.active && best_test_inliers >= options_.pretest_min_best_inliers) {
          test_scorer.Residuals(model, &test_residuals);
          if (CountInliers(test_residuals, max_sq_error) <
              options_.pretest_min_ratio * best_test_inliers) {
            continue;
          }
        }
        scorer.Residuals(model, &residuals);
        double cost = TruncatedCost(residuals, max_sq_error);
        if (!(cost < best_cost)) continue;
        report.model = model;
        if (options_.local_optimization) {
          // LO-RANSAC: polish every new so-far-best model (this only lowers its
          // cost), so that hypotheses are ranked by their refitted cost, not by
          // the luck of the minimal sample's noise.
          cost = LocallyOptimize(X, Y, scorer, max_sq_error, &report.model, &residuals);
        }
        best_cost = cost;
        best_support = CountInliers(residuals, max_sq_error);
        best_test_inliers = 0;
        for (int i : test.index) best_test_inliers += residuals[i] <= max_sq_error ? 1 : 0;
        dynamic_max_trials = local ? LocalNumTrials(residuals, pool, *local, max_sq_error,
                                                    min_trials, max_trials)
                                   : UniformNumTrials(residuals, pool, max_sq_error, min_trials,
                                                      max_trials);
      }
    }
    report.num_trials = trial;
    if (best_support < kSample) return report;
    Finish(scorer, static_cast<int>(X.size()), max_sq_error, &report);
    return report;
  }

  // No random search: every model of `initial_models` (e.g. the previous
  // frame's model, or one from another estimator) is scored on all points and,
  // with local_optimization, polished as a so-far-best hypothesis would be;
  // the report is the best of them (num_trials = 0), as Estimate's would be
  // with these as its only hypotheses. Failure as Estimate's (sizes differ,
  // max_error <= 0, or fewer than kMinNumSamples inliers).
  Report Polish(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                const std::vector<M_t>& initial_models) const {
    Report report;
    if (X.size() != Y.size() || !(options_.max_error > 0.0)) return report;
    const double max_sq_error = options_.max_error * options_.max_error;
    const internal::ScorerFor<Estimator> scorer(X, Y);
    std::vector<double> residuals;
    double best_cost = std::numeric_limits<double>::infinity();
    int best_support = 0;
    for (const M_t& initial : initial_models) {
      M_t model = initial;
      scorer.Residuals(model, &residuals);
      double cost = TruncatedCost(residuals, max_sq_error);
      if (options_.local_optimization) {
        cost = LocallyOptimize(X, Y, scorer, max_sq_error, &model, &residuals);
      }
      if (!(cost < best_cost)) continue;
      best_cost = cost;
      best_support = CountInliers(residuals, max_sq_error);
      report.model = model;
    }
    if (best_support < Estimator::kMinNumSamples) return report;
    Finish(scorer, static_cast<int>(X.size()), max_sq_error, &report);
    return report;
  }

 private:
  // Local sampling: each pool point's neighbours within the pool, flattened
  // (point pool[k]'s are nb[begin[k] .. begin[k + 1])).
  struct LocalNeighbours {
    std::vector<int> begin, nb;
  };
  // The pre-test set (RansacOptions::pretest_points): distinct random points.
  struct Pretest {
    bool active = false;
    std::vector<int> index;
    std::vector<X_t> x;
    std::vector<Y_t> y;
  };

  // The pool to sample from: all points, or the distinct indices of
  // `sample_from` (false when one is out of range).
  static bool MakePool(int num_points, const std::vector<int>* sample_from,
                       std::vector<int>* pool_out) {
    std::vector<int>& pool = *pool_out;
    if (sample_from == nullptr) {
      pool.resize(num_points);
      for (int i = 0; i < num_points; ++i) pool[i] = i;
      return true;
    }
    pool = *sample_from;
    for (int i : pool) {
      if (i < 0 || i >= num_points) return false;
    }
    std::sort(pool.begin(), pool.end());
    pool.erase(std::unique(pool.begin(), pool.end()), pool.end());
    return true;
  }

  static LocalNeighbours MakeLocalNeighbours(const std::vector<int>& pool,
                                             const std::vector<std::vector<int>>& neighbours,
                                             int num_points) {
    LocalNeighbours local;
    std::vector<char> in_pool(num_points, 0);
    for (int i : pool) in_pool[i] = 1;
    local.begin.reserve(pool.size() + 1);
    for (int i : pool) {
      local.begin.push_back(static_cast<int>(local.nb.size()));
      for (int j : neighbours[i]) {
        if (j >= 0 && j < num_points && j != i && in_pool[j]) local.nb.push_back(j);
      }
    }
    local.begin.push_back(static_cast<int>(local.nb.size()));
    return local;
  }

  // Pre-test set: distinct random points, by a generator of its own.
  Pretest MakePretest(const std::vector<X_t>& X, const std::vector<Y_t>& Y) const {
    Pretest test;
    const int num_points = static_cast<int>(X.size());
    test.active = options_.pretest_points > 0 && num_points >= 2 * options_.pretest_points;
    if (!test.active) return test;
    std::mt19937_64 test_rng(options_.seed ^ 0x5DEECE66Dull);
    std::vector<int> all(num_points);
    for (int i = 0; i < num_points; ++i) all[i] = i;
    for (int s = 0; s < options_.pretest_points; ++s) {
      const int j = s + static_cast<int>(internal::UniformIndex(test_rng, num_points - s));
      std::swap(all[s], all[j]);
      test.index.push_back(all[s]);
      test.x.push_back(X[all[s]]);
      test.y.push_back(Y[all[s]]);
    }
    return test;
  }

  // A minimal sample into sample_x/y: uniform from the pool, or (local) a
  // uniform pool point and the rest from its neighbours (see the file comment).
  static void DrawSample(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                         const LocalNeighbours* local, std::mt19937_64* rng,
                         std::vector<int>* pool_io, std::vector<int>* scratch_io,
                         std::vector<X_t>* sample_x_out, std::vector<Y_t>* sample_y_out) {
    constexpr int kSample = Estimator::kMinNumSamples;
    std::vector<int>& pool = *pool_io;
    std::vector<int>& scratch = *scratch_io;
    std::vector<X_t>& sample_x = *sample_x_out;
    std::vector<Y_t>& sample_y = *sample_y_out;
    const int pool_size = static_cast<int>(pool.size());
    if (local == nullptr) {
      // Partial Fisher-Yates: pool[0..kSample) becomes a uniform random sample
      // (valid from any current order of the pool).
      for (int s = 0; s < kSample; ++s) {
        const int j = s + static_cast<int>(internal::UniformIndex(*rng, pool_size - s));
        std::swap(pool[s], pool[j]);
        sample_x[s] = X[pool[s]];
        sample_y[s] = Y[pool[s]];
      }
      return;
    }
    // The pool keeps its order here: local->begin is indexed by position.
    const int k = static_cast<int>(internal::UniformIndex(*rng, pool_size));
    const int num_nb = local->begin[k + 1] - local->begin[k];
    sample_x[0] = X[pool[k]];
    sample_y[0] = Y[pool[k]];
    if (num_nb >= kSample - 1) {
      scratch.assign(local->nb.begin() + local->begin[k], local->nb.begin() + local->begin[k + 1]);
      for (int s = 0; s < kSample - 1; ++s) {
        const int j = s + static_cast<int>(internal::UniformIndex(*rng, num_nb - s));
        std::swap(scratch[s], scratch[j]);
        sample_x[s + 1] = X[scratch[s]];
        sample_y[s + 1] = Y[scratch[s]];
      }
      return;
    }
    // An isolated point: the rest of the sample from the whole pool
    // (distinct positions, by rejection).
    scratch.assign(1, k);
    while (static_cast<int>(scratch.size()) < kSample) {
      const int j = static_cast<int>(internal::UniformIndex(*rng, pool_size));
      if (std::find(scratch.begin(), scratch.end(), j) != scratch.end()) continue;
      sample_x[scratch.size()] = X[pool[j]];
      sample_y[scratch.size()] = Y[pool[j]];
      scratch.push_back(j);
    }
  }

  // The adaptive trial count for uniform samples from the pool's inlier ratio.
  int UniformNumTrials(const std::vector<double>& residuals, const std::vector<int>& pool,
                       double max_sq_error, int min_trials, int max_trials) const {
    int pool_inliers = 0;
    for (int i : pool) pool_inliers += residuals[i] <= max_sq_error ? 1 : 0;
    return internal::RansacNumTrials(static_cast<double>(pool_inliers) / pool.size(),
                                     Estimator::kMinNumSamples, options_.confidence, min_trials,
                                     max_trials);
  }

  // The adaptive trial count for local samples: p(all-inlier local sample),
  // see the file comment, as a "ratio" with sample size 1.
  int LocalNumTrials(const std::vector<double>& residuals, const std::vector<int>& pool,
                     const LocalNeighbours& local, double max_sq_error, int min_trials,
                     int max_trials) const {
    constexpr int kSample = Estimator::kMinNumSamples;
    const int pool_size = static_cast<int>(pool.size());
    int pool_inliers = 0;
    for (int i : pool) pool_inliers += residuals[i] <= max_sq_error ? 1 : 0;
    double p_sum = 0.0;
    for (int k = 0; k < pool_size; ++k) {
      if (!(residuals[pool[k]] <= max_sq_error)) continue;
      int b = local.begin[k + 1] - local.begin[k];
      int a = 0;
      if (b >= kSample - 1) {
        for (int q = local.begin[k]; q < local.begin[k + 1]; ++q) {
          a += residuals[local.nb[q]] <= max_sq_error ? 1 : 0;
        }
      } else {  // isolated: the rest from the pool
        b = pool_size - 1;
        a = pool_inliers - 1;
      }
      double prod = 1.0;
      for (int s = 0; s < kSample - 1; ++s) {
        prod *= static_cast<double>(std::max(0, a - s)) / (b - s);
      }
      p_sum += prod;
    }
    return internal::RansacNumTrials(p_sum / pool_size, 1, options_.confidence, min_trials,
                                     max_trials);
  }

  // The inlier mask and support of report.model; success iff the support is
  // at least kMinNumSamples.
  static void Finish(const internal::ScorerFor<Estimator>& scorer, int num_points,
                     double max_sq_error, Report* report_out) {
    Report& report = *report_out;
    std::vector<double> residuals;
    scorer.Residuals(report.model, &residuals);
    report.inlier_mask.assign(num_points, 0);
    report.support = 0;
    for (int i = 0; i < num_points; ++i) {
      if (residuals[i] <= max_sq_error) {
        report.inlier_mask[i] = 1;
        ++report.support;
      }
    }
    report.success = report.support >= Estimator::kMinNumSamples;
    if (!report.success) report.inlier_mask.clear();
  }

  // Least-squares refits of `model`, kept while they lower the MSAC cost at
  // max_error. The first refits take the inliers at kLoThresholdMultipliers x
  // max_error (widest first): a model from a noisy minimal sample is often off
  // by more than max_error at the far side of its structure, so its own inlier
  // set is only part of it, and refitting on that part converges to the
  // partial set. Then it iterates at max_error until the inliers are stable.
  // `residuals` holds the model's squared residuals on entry and on exit.
  // Returns the final MSAC cost.
  static double LocallyOptimize(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                                const internal::ScorerFor<Estimator>& scorer, double max_sq_error,
                                M_t* model, std::vector<double>* residuals) {
    double cost = TruncatedCost(*residuals, max_sq_error);
    std::vector<X_t> inlier_x;
    std::vector<Y_t> inlier_y;
    std::vector<M_t> models;
    std::vector<double> refit_residuals;
    // One refit on the points within `sq_threshold`; true if it was kept.
    auto refit_once = [&](double sq_threshold, bool* same_inliers) {
      inlier_x.clear();
      inlier_y.clear();
      for (size_t i = 0; i < X.size(); ++i) {
        if ((*residuals)[i] <= sq_threshold) {
          inlier_x.push_back(X[i]);
          inlier_y.push_back(Y[i]);
        }
      }
      models.clear();
      Estimator::Estimate(inlier_x, inlier_y, &models);
      for (const M_t& refit : models) {
        scorer.Residuals(refit, &refit_residuals);
        const double refit_cost = TruncatedCost(refit_residuals, max_sq_error);
        if (!(refit_cost < cost)) continue;
        *same_inliers = SameInliers(*residuals, refit_residuals, max_sq_error);
        cost = refit_cost;
        *model = refit;
        residuals->swap(refit_residuals);
        return true;
      }
      return false;
    };
    bool same_inliers = false;
    for (double multiplier : kLoThresholdMultipliers) {
      refit_once(multiplier * multiplier * max_sq_error, &same_inliers);
    }
    for (int iter = 0; iter < kMaxLocalOptimizationIterations; ++iter) {
      if (!refit_once(max_sq_error, &same_inliers) || same_inliers) break;
    }
    return cost;
  }

  static int CountInliers(const std::vector<double>& sq_residuals, double max_sq_error) {
    int count = 0;
    for (double r : sq_residuals) count += r <= max_sq_error ? 1 : 0;
    return count;
  }

  // MSAC cost: sum over all points of min(r^2, max_error^2).
  // Four partial sums: one chain of additions is bound by their latency, and
  // this runs once per hypothesis over all points.
  static double TruncatedCost(const std::vector<double>& sq_residuals, double max_sq_error) {
    double cost[4] = {0.0, 0.0, 0.0, 0.0};
    const size_t n = sq_residuals.size();
    size_t i = 0;
    for (; i + 4 <= n; i += 4) {
      for (int k = 0; k < 4; ++k) cost[k] += std::min(sq_residuals[i + k], max_sq_error);
    }
    for (; i < n; ++i) cost[0] += std::min(sq_residuals[i], max_sq_error);
    return (cost[0] + cost[1]) + (cost[2] + cost[3]);
  }

  static bool SameInliers(const std::vector<double>& a, const std::vector<double>& b,
                          double max_sq_error) {
    for (size_t i = 0; i < a.size(); ++i) {
      if ((a[i] <= max_sq_error) != (b[i] <= max_sq_error)) return false;
    }
    return true;
  }

  RansacOptions options_;
};

}  // namespace slapse
