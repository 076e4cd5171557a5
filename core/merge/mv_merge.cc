#include "core/merge/mv_merge.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "core/common/mb_grid.h"

namespace slapse {
namespace {

double BinomialPmf(int n, int k, double q) {
  double c = 1.0;
  for (int i = 1; i <= k; ++i) c = c * (n - k + i) / i;
  return c * std::pow(q, k) * std::pow(1.0 - q, n - k);
}

// The one rule naming a segment by its anchors' picture types.
SegmentType SegmentTypeOf(bool earlier_i, bool later_i) {
  return later_i ? (earlier_i ? SegmentType::kII : SegmentType::kPI)
                 : (earlier_i ? SegmentType::kIP : SegmentType::kPP);
}

bool EarlierIsI(SegmentType type) { return type == SegmentType::kIP || type == SegmentType::kII; }
bool LaterIsI(SegmentType type) { return type == SegmentType::kPI || type == SegmentType::kII; }

}  // namespace

const char* SegmentTypeName(SegmentType type) {
  switch (type) {
    case SegmentType::kIP:
      return "IP";
    case SegmentType::kPP:
      return "PP";
    case SegmentType::kPI:
      return "PI";
    case SegmentType::kII:
      return "II";
  }
  return "?";
}

double MergedVariance(int n_direct, int n_indirect, double sigma_px) {
  // Direct: variance s^2, weight 2; indirect: variance 2 s^2, weight 1.
  // Var(sum w_i m_i / sum w_i) = sum w_i^2 var_i / (sum w_i)^2
  //   = (4 n_d s^2 + 2 n_i s^2) / (2 n_d + n_i)^2 = 2 s^2 / (2 n_d + n_i).
  const int w = 2 * n_direct + n_indirect;
  return w > 0 ? 2.0 * sigma_px * sigma_px / w : INFINITY;
}

double ImvExistenceProbability(bool has_direct, int n_b, double p) {
  const double none_indirect = std::pow(1.0 - p * p, n_b);
  return 1.0 - (has_direct ? (1.0 - p) : 1.0) * none_indirect;
}

double ExpectedMergedVariance(bool has_direct, int n_b, double p, double sigma_px, int min_imvs) {
  const double q = p * p;
  double sum = 0.0, mass = 0.0;
  for (int nd = 0; nd <= (has_direct ? 1 : 0); ++nd) {
    const double pd = has_direct ? (nd == 1 ? p : 1.0 - p) : 1.0;
    for (int ni = 0; ni <= n_b; ++ni) {
      if (nd + ni < std::max(min_imvs, 1)) continue;  // conditioned on enough IMVs
      const double pr = pd * BinomialPmf(n_b, ni, q);
      sum += pr * MergedVariance(nd, ni, sigma_px);
      mass += pr;
    }
  }
  return mass > 0 ? sum / mass : INFINITY;
}

double MergeNoiseGatePx(bool a_direct, bool b_direct, double sigma_px,
                        const MergeOptions& options) {
  const double var_a = (a_direct ? 1.0 : 2.0) * sigma_px * sigma_px;
  const double var_b = (b_direct ? 1.0 : 2.0) * sigma_px * sigma_px;
  return std::max(options.gate_sigmas * std::sqrt(var_a + var_b), options.gate_min_px);
}

std::optional<MergedMv> MergeCell(const MvCandidate* candidates, size_t n, double sigma_px,
                                  const MergeOptions& options) {
  if (n == 0) return std::nullopt;
  // Two candidates agree when their displacements differ by less than the gate
  // for the variance of their difference (MergeNoiseGatePx). Computed per
  // test: a cell has a handful of candidates, and buffers here were an
  // allocation per cell.
  auto disp = [&](size_t i) -> Eigen::Vector2d {
    return candidates[i].earlier_px - candidates[i].later_px;
  };
  // Two direct candidates at different places in the cell (partitions of
  // one macroblock) may also differ by the flow's change between them
  // (MergeOptions::gate_flow_gradient_per_px). Not an indirect one: its
  // later point y + g moves with a wrong g, and so would the allowance.
  auto agree = [&](size_t i, size_t j) {
    const Eigen::Vector2d d_i = disp(i), d_j = disp(j);
    double gate = MergeNoiseGatePx(candidates[i].direct, candidates[j].direct, sigma_px, options);
    if (candidates[i].direct && candidates[j].direct) {
      gate += options.gate_flow_gradient_per_px *
              (candidates[i].later_px - candidates[j].later_px).norm() *
              std::min(d_i.norm(), d_j.norm());
    }
    return (d_i - d_j).norm() <= gate;
  };
  // Seed: the candidate that the most weight of *other* candidates agrees
  // with (ties: the heavier, i.e. direct, candidate).
  size_t seed = 0;
  double best_support = -1.0;
  for (size_t i = 0; i < n; ++i) {
    double support = 0.0;
    for (size_t j = 0; j < n; ++j) {
      if (j != i && agree(i, j)) support += candidates[j].direct ? 2.0 : 1.0;
    }
    if (support > best_support ||
        (support == best_support && candidates[i].direct && !candidates[seed].direct)) {
      seed = i;
      best_support = support;
    }
  }
  // Several candidates and none agrees with another: no way to tell the
  // in-line MV from the wrong matches, so the cell gives no correspondence.
  if (n > 1 && best_support == 0.0) return std::nullopt;

  MergedMv out;
  out.later_px.setZero();
  out.earlier_px.setZero();
  double weight_sum = 0.0;
  for (size_t i = 0; i < n; ++i) {
    if (!agree(seed, i)) continue;
    const MvCandidate& c = candidates[i];
    const double w = c.direct ? 2.0 : 1.0;
    out.later_px += w * c.later_px;
    out.earlier_px += w * c.earlier_px;
    weight_sum += w;
    (c.direct ? out.n_direct : out.n_indirect)++;
  }
  out.later_px /= weight_sum;
  out.earlier_px /= weight_sum;
  out.variance_px2 = MergedVariance(out.n_direct, out.n_indirect, sigma_px);
  return out;
}

std::optional<MergedMv> MergeCell(const std::vector<MvCandidate>& candidates, double sigma_px,
                                  const MergeOptions& options) {
  return MergeCell(candidates.data(), candidates.size(), sigma_px, options);
}

SegmentMerger::SegmentMerger(int width_px, int height_px, double sigma_px, MergeOptions options)
    : width_px_(width_px),
      height_px_(height_px),
      mb_cols_(MbCount(width_px)),
      mb_rows_(MbCount(height_px)),
      sigma_px_(sigma_px),
      options_(options) {}

void SegmentMerger::Reset() {
  earlier_.reset();
  b_frames_.clear();
  chain_.reset();
  extend_next_ = false;
  last_had_b_ = false;
}

bool SegmentMerger::ExtendChain(AnchorPair pair) {
  if (!earlier_.has_value() || pair.later_index != earlier_->index ||
      pair.correspondences.empty() || last_had_b_) {
    return false;
  }
  chain_ = std::move(pair);
  extend_next_ = true;
  return true;
}

std::optional<AnchorPair> SegmentMerger::Flush() {
  if (extend_next_ || !chain_.has_value() || !earlier_.has_value() ||
      chain_->later_index != earlier_->index) {
    return std::nullopt;
  }
  std::optional<AnchorPair> open = std::move(chain_);
  chain_.reset();
  return open;
}

int SegmentMerger::CellOf(const Eigen::Vector2d& x_px) const {
  // The MB grid of core/common/mb_grid.h.
  const MbCell cell = MbCellOfPixel(x_px);
  const int col = cell.col, row = cell.row;
  if (col < 0 || row < 0 || col >= mb_cols_ || row >= mb_rows_) return -1;
  if (x_px.x() > width_px_ - 0.5 || x_px.y() > height_px_ - 0.5) return -1;
  return row * mb_cols_ + col;
}

namespace {

// A chain cut short by a segment that cannot be composed onto it (an I
// frame; B frames after a handed-back pair): `pair`, the pair into the
// cut's anchor, is made to start at the chain's first anchor, so
// consecutive pairs still share their anchors. Dropping the short
// chain instead left the frames between the last emitted anchor and the
// pair's earlier one out of every pair while their time passed (the filter
// and the window refiner then disagreed on the step's span).
void StartAtChain(const AnchorPair& chain, AnchorPair* pair) {
  pair->earlier_index = chain.earlier_index;
  pair->earlier_timestamp_s = chain.earlier_timestamp_s;
  pair->n_b = static_cast<int>(pair->later_index - pair->earlier_index - 1);
  pair->type = SegmentTypeOf(EarlierIsI(chain.type), LaterIsI(pair->type));
}

}  // namespace

std::optional<AnchorPair> SegmentMerger::Push(const FrameRecord& frame) {
  if (frame.type == PictureType::kB) {
    b_frames_seen_ = true;
    // Keep only B frames that sit between the current anchor and a later one.
    for (const FrameRecord& b : b_frames_) {
      if (frame.coded_index >= 0 && b.coded_index > frame.coded_index) b_pyramid_seen_ = true;
    }
    if (earlier_.has_value() && frame.prev_anchor_index == earlier_->index && !frame.corrupt) {
      b_frames_.push_back(frame);
    }
    // A chain still shorter than min_pair_span_s when the first B frame
    // comes (a stream with adaptive B frames): the B segment cannot be
    // composed onto it, so it is emitted as it is; dropped, its frames would
    // fall between two pairs. A handed-back pair (ExtendChain) stays with
    // the rule of a chain cut short (Push of the next anchor).
    return Flush();
  }
  if (!IsAnchor(frame.type)) return std::nullopt;
  std::optional<AnchorPair> pair;
  if (earlier_.has_value()) pair = Build(frame);
  const bool chainable = pair.has_value() && frame.type == PictureType::kP && b_frames_.empty() &&
                         (extend_next_ || ShorterThanMinSpan(*pair));
  if (chainable) {
    pair = Chain(std::move(*pair));
  } else if (pair.has_value() && chain_.has_value() && chain_->later_index == pair->earlier_index &&
             (extend_next_ || pair->correspondences.empty())) {
    // A chain cut short by an anchor without vectors (an I frame), or a
    // handed-back pair (ExtendChain) by a segment that cannot be composed
    // onto it: the pair starts at the chain's first anchor; its vectors,
    // which end at the chain's last anchor, are dropped.
    StartAtChain(*chain_, &*pair);
    pair->correspondences.clear();
    chain_.reset();
  } else {
    chain_.reset();
  }
  extend_next_ = false;
  last_had_b_ = !b_frames_.empty();
  earlier_ = frame;
  earlier_->mvs.clear();
  earlier_->luma.clear();
  earlier_->mb_texture.clear();
  b_frames_.clear();
  return pair;
}

bool SegmentMerger::ChainLookup(const std::vector<const Correspondence*>& by_cell,
                                const Eigen::Vector2d& x, Eigen::Vector2d* start,
                                double* variance) const {
  // Displacement field D(c) = start(c) - later(c) on the cells of the chain's
  // last anchor, interpolated bilinearly between the four cell centres around
  // x; where one of them is empty, the cell containing x alone.
  const double u = (x.x() - MbCentrePx(0)) / kMbSizePx, v = (x.y() - MbCentrePx(0)) / kMbSizePx;
  const int c0 = static_cast<int>(std::floor(u)), r0 = static_cast<int>(std::floor(v));
  const double fu = u - c0, fv = v - r0;
  Eigen::Vector2d disp = Eigen::Vector2d::Zero();
  double var = 0.0;
  bool all = true;
  for (int dr = 0; dr < 2 && all; ++dr) {
    for (int dc = 0; dc < 2 && all; ++dc) {
      const int col = c0 + dc, row = r0 + dr;
      const Correspondence* c = (col >= 0 && row >= 0 && col < mb_cols_ && row < mb_rows_)
                                    ? by_cell[row * mb_cols_ + col]
                                    : nullptr;
      if (c == nullptr) {
        all = false;
        break;
      }
      const double w = (dc ? fu : 1 - fu) * (dr ? fv : 1 - fv);
      disp += w * (c->x_earlier_px - c->x_later_px);
      var += w * c->variance_px2;
    }
  }
  if (!all) {
    const int cell = CellOf(x);
    if (cell < 0 || by_cell[cell] == nullptr) return false;
    disp = by_cell[cell]->x_earlier_px - by_cell[cell]->x_later_px;
    var = by_cell[cell]->variance_px2;
  }
  *start = x + disp;
  *variance = var;
  return true;
}

std::optional<AnchorPair> SegmentMerger::Chain(AnchorPair step) {
  if (chain_.has_value() && chain_->later_index == step.earlier_index) {
    // Compose: a point of the new anchor -> the previous anchor (this step's
    // vector) -> the chain's first anchor (the chain's field there).
    AnchorPair chained = step;
    chained.earlier_index = chain_->earlier_index;
    chained.earlier_timestamp_s = chain_->earlier_timestamp_s;
    chained.type = SegmentTypeOf(EarlierIsI(chain_->type), /*later_i=*/false);
    chained.n_b = static_cast<int>(chained.later_index - chained.earlier_index - 1);
    chained.correspondences.clear();
    std::vector<const Correspondence*> by_cell(static_cast<size_t>(mb_cols_) * mb_rows_, nullptr);
    for (const Correspondence& c : chain_->correspondences) by_cell[c.mb_index] = &c;
    for (const Correspondence& c : step.correspondences) {
      Eigen::Vector2d start;
      double var;
      if (!ChainLookup(by_cell, c.x_earlier_px, &start, &var)) continue;
      Correspondence out = c;
      out.x_earlier_px = start;
      out.variance_px2 = c.variance_px2 + var;  // independent errors add
      chained.correspondences.push_back(out);
    }
    chain_ = std::move(chained);
  } else {
    chain_ = std::move(step);
  }
  if (!extend_next_ && ShorterThanMinSpan(*chain_)) {
    return std::nullopt;
  }
  std::optional<AnchorPair> done = std::move(chain_);
  chain_.reset();
  return done;
}

std::vector<const MotionVector*> SegmentMerger::DirectVectors(const FrameRecord& later) const {
  std::vector<const MotionVector*> past;
  for (const MotionVector& mv : later.mvs) {
    if (mv.direction == RefDirection::kPast) past.push_back(&mv);
  }
  if (later.reference_certain || options_.uncertain_refs == MergeOptions::UncertainRefs::kKeep) {
    return past;
  }
  if (options_.uncertain_refs == MergeOptions::UncertainRefs::kDrop) return {};
  return ConsistentVectors(past);
}

int64_t SegmentMerger::FirstDecodedB(int64_t later_index) const {
  int64_t first = -1;
  for (const FrameRecord& b : b_frames_) {
    if (b.next_anchor_index != later_index || b.coded_index < 0) continue;
    if (first < 0 || b.coded_index < first) first = b.coded_index;
  }
  return first;
}

std::vector<const MotionVector*> SegmentMerger::IndirectVectors(const FrameRecord& b) const {
  std::vector<const MotionVector*> past, all;
  const bool filter_past =
      !b.reference_certain && options_.uncertain_refs != MergeOptions::UncertainRefs::kKeep;
  for (const MotionVector& mv : b.mvs) {
    (filter_past && mv.direction == RefDirection::kPast ? past : all).push_back(&mv);
  }
  if (!filter_past) return all;  // every vector as it is (MPEG-2, plain B frames)
  if (options_.uncertain_refs == MergeOptions::UncertainRefs::kConsistent) {
    past = ConsistentVectors(past);
    all.insert(all.end(), past.begin(), past.end());
  }
  return all;
}

std::vector<const MotionVector*> SegmentMerger::ConsistentVectors(
    const std::vector<const MotionVector*>& vectors) const {
  // Each vector against the component-wise median m of the vectors whose
  // blocks lie in the 3x3 macroblocks around its own; kept if
  //   |v - m| <= max(consistent_min_px, consistent_rel |m|).
  // With locally constant motion a vector to the reference n frames back is
  // about n m: |v - m| = (n - 1) |m| fails for n >= 2 once |m| exceeds
  // consistent_min_px / (n - 1 - consistent_rel)... i.e. wherever the two
  // references differ by more than the gate. (Its neighbours using the older
  // reference too would pass: a whole region on one older reference is not
  // detected; the pair's robust estimators see it as an outlier region.)
  std::vector<std::vector<const MotionVector*>> by_cell(static_cast<size_t>(mb_cols_) * mb_rows_);
  for (const MotionVector* mv : vectors) {
    const int cell = CellOf(Eigen::Vector2d(mv->x_px, mv->y_px));
    if (cell >= 0) by_cell[cell].push_back(mv);
  }
  // The median of the 3x3 cells around (row, col); false with fewer than 3
  // vectors there (too few neighbours to tell). The same for every vector of
  // a cell: computed once per cell (rows and columns -1 .. size, where
  // vectors at the frame's edge fall).
  std::vector<double> xs, ys;
  auto neighbourhood_median = [&](int row0, int col0, Eigen::Vector2d* m) {
    xs.clear();
    ys.clear();
    for (int row = row0 - 1; row <= row0 + 1; ++row) {
      for (int col = col0 - 1; col <= col0 + 1; ++col) {
        if (row < 0 || col < 0 || row >= mb_rows_ || col >= mb_cols_) continue;
        for (const MotionVector* n : by_cell[row * mb_cols_ + col]) {
          xs.push_back(n->dx_px);
          ys.push_back(n->dy_px);
        }
      }
    }
    if (xs.size() < 3) return false;
    std::nth_element(xs.begin(), xs.begin() + xs.size() / 2, xs.end());
    std::nth_element(ys.begin(), ys.begin() + ys.size() / 2, ys.end());
    *m = Eigen::Vector2d(xs[xs.size() / 2], ys[ys.size() / 2]);
    return true;
  };
  const int padded_cols = mb_cols_ + 2;
  enum : char { kUnknown, kNone, kKnown };
  std::vector<char> state(static_cast<size_t>(mb_rows_ + 2) * padded_cols, kUnknown);
  std::vector<Eigen::Vector2d> medians(state.size());
  std::vector<const MotionVector*> kept;
  for (const MotionVector* mv : vectors) {
    const MbCell c = MbCellOfPixel(Eigen::Vector2d(mv->x_px, mv->y_px));
    Eigen::Vector2d m;
    if (c.row >= -1 && c.col >= -1 && c.row <= mb_rows_ && c.col <= mb_cols_) {
      const size_t k = static_cast<size_t>(c.row + 1) * padded_cols + (c.col + 1);
      if (state[k] == kUnknown)
        state[k] = neighbourhood_median(c.row, c.col, &medians[k]) ? kKnown : kNone;
      if (state[k] == kNone) continue;
      m = medians[k];
    } else if (!neighbourhood_median(c.row, c.col, &m)) {
      continue;
    }
    const Eigen::Vector2d v(mv->dx_px, mv->dy_px);
    if ((v - m).norm() <=
        std::max(options_.consistent_min_px, options_.consistent_rel * m.norm())) {
      kept.push_back(mv);
    }
  }
  return kept;
}

AnchorPair SegmentMerger::Build(const FrameRecord& later) const {
  AnchorPair pair;
  pair.earlier_index = earlier_->index;
  pair.later_index = later.index;
  pair.earlier_timestamp_s = earlier_->timestamp_s;
  pair.later_timestamp_s = later.timestamp_s;
  pair.n_b = static_cast<int>(later.index - earlier_->index - 1);
  pair.mb_cols = mb_cols_;
  pair.mb_rows = mb_rows_;
  pair.type = SegmentTypeOf(earlier_->type == PictureType::kI, later.type == PictureType::kI);

  // Every candidate with its cell, in the order found; bucketed by cell below.
  std::vector<std::pair<int, MvCandidate>> found;
  // Direct: the later P frame's past vectors refer to the earlier anchor.
  if (options_.use_direct && later.type == PictureType::kP &&
      later.prev_anchor_index == earlier_->index && !later.corrupt) {
    for (const MotionVector* mv : DirectVectors(later)) {
      const Eigen::Vector2d start(mv->x_px, mv->y_px);
      const int cell = CellOf(start);
      if (cell < 0) continue;
      found.push_back({cell, {start, start + Eigen::Vector2d(mv->dx_px, mv->dy_px), true}});
    }
  }
  // Indirect: B blocks with both a past (f) and a future (g) vector. Under a
  // B-pyramid only the segment's first-decoded B frame (pyramid_top_b).
  if (options_.use_indirect && (!b_pyramid_seen_ || options_.pyramid_top_b)) {
    // The top is decoded right after the later anchor; a first-decoded B that
    // is not (the top was corrupt and dropped) may refer to the top.
    int64_t top_coded = b_pyramid_seen_ ? FirstDecodedB(later.index) : -1;
    if (top_coded >= 0 && later.coded_index >= 0 && top_coded != later.coded_index + 1) {
      top_coded = -1;
    }
    std::vector<const MotionVector*> sorted_mvs;
    for (const FrameRecord& b : b_frames_) {
      if (b.next_anchor_index != later.index) continue;
      if (b_pyramid_seen_ && (top_coded < 0 || b.coded_index != top_coded)) continue;
      // FFmpeg exports a bi-predicted block as two entries with the same block:
      // sorted stably by block (x, y, w, h), each block's last past (f) and
      // last future (g) vector pair up, blocks in ascending order. (A sort,
      // not a map: no allocation per block.)
      auto block_of = [](const MotionVector* mv) {
        return std::make_tuple(mv->x_px, mv->y_px, mv->w_px, mv->h_px);
      };
      sorted_mvs = IndirectVectors(b);
      std::stable_sort(
          sorted_mvs.begin(), sorted_mvs.end(),
          [&](const MotionVector* x, const MotionVector* y) { return block_of(x) < block_of(y); });
      for (size_t first = 0, next = 0; first < sorted_mvs.size(); first = next) {
        const MotionVector* f = nullptr;
        const MotionVector* g = nullptr;
        for (next = first;
             next < sorted_mvs.size() && block_of(sorted_mvs[next]) == block_of(sorted_mvs[first]);
             ++next) {
          (sorted_mvs[next]->direction == RefDirection::kPast ? f : g) = sorted_mvs[next];
        }
        if (f == nullptr || g == nullptr) continue;
        const Eigen::Vector2d y(f->x_px, f->y_px);
        const Eigen::Vector2d start = y + Eigen::Vector2d(g->dx_px, g->dy_px);
        const Eigen::Vector2d end = y + Eigen::Vector2d(f->dx_px, f->dy_px);
        const int cell = CellOf(start);
        if (cell < 0) continue;
        found.push_back({cell, {start, end, false}});
      }
    }
  }
  // A stable counting sort by cell (each cell's candidates keep their order):
  // cell c's are candidates[begin[c] .. begin[c + 1]).
  const size_t num_cells = static_cast<size_t>(mb_cols_) * mb_rows_;
  std::vector<int> begin(num_cells + 1, 0);
  for (const auto& [cell, candidate] : found) ++begin[cell + 1];
  for (size_t c = 0; c < num_cells; ++c) begin[c + 1] += begin[c];
  std::vector<MvCandidate> candidates(found.size());
  {
    std::vector<int> at(begin.begin(), begin.end() - 1);
    for (const auto& [cell, candidate] : found) candidates[at[cell]++] = candidate;
  }
  const bool gate_texture = options_.min_mb_texture > 0 && later.mb_texture.size() == num_cells;
  for (size_t cell = 0; cell < num_cells; ++cell) {
    if (gate_texture && later.mb_texture[cell] < options_.min_mb_texture) continue;
    const auto merged =
        MergeCell(candidates.data() + begin[cell],
                  static_cast<size_t>(begin[cell + 1] - begin[cell]), sigma_px_, options_);
    if (!merged.has_value()) continue;
    Correspondence c;
    c.x_later_px = merged->later_px;
    c.x_earlier_px = merged->earlier_px;
    c.variance_px2 = merged->variance_px2;
    c.mb_index = static_cast<int>(cell);
    c.n_direct = merged->n_direct;
    c.n_indirect = merged->n_indirect;
    pair.correspondences.push_back(c);
  }
  return pair;
}

}  // namespace slapse
