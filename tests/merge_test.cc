// MV merging: Lemma 1 and Lemma 2 against Monte Carlo simulation, gating,
// the weighted start/end merge, and segment assembly from frame records.
#include "core/merge/mv_merge.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "core/mv/mv_reader.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

constexpr double kSigma = 0.25;  // MPEG-2 half-pel

// Monte Carlo model of one macroblock (paper Sec. III-B): each block match is
// correct with probability p, its error N(0, sigma^2) per axis; a wrong match
// lands anywhere within +-16 px. An indirect MV is correct only when both its
// B-frame vectors are.
struct McCell {
  std::vector<MvCandidate> candidates;
  int n_direct_correct = 0, n_indirect_correct = 0;
};

McCell SimulateCell(std::mt19937_64& rng, bool has_direct, int n_b, double p,
                    const Eigen::Vector2d& true_m, bool include_wrong) {
  std::normal_distribution<double> noise(0.0, kSigma);
  std::uniform_real_distribution<double> unit(0.0, 1.0), garbage(-16.0, 16.0);
  McCell cell;
  const Eigen::Vector2d centre(100, 100);
  if (has_direct) {
    const bool ok = unit(rng) < p;
    const Eigen::Vector2d m = ok ? true_m + Eigen::Vector2d(noise(rng), noise(rng))
                                 : Eigen::Vector2d(garbage(rng), garbage(rng));
    cell.n_direct_correct += ok;
    if (ok || include_wrong) cell.candidates.push_back({centre, centre + m, true});
  }
  for (int b = 0; b < n_b; ++b) {
    const bool f_ok = unit(rng) < p, g_ok = unit(rng) < p;
    const Eigen::Vector2d f_err(noise(rng), noise(rng)), g_err(noise(rng), noise(rng));
    // Block at y in the B frame; the true displacement is split as f - g = m.
    const Eigen::Vector2d y = centre + Eigen::Vector2d(unit(rng) * 8 - 4, unit(rng) * 8 - 4);
    const Eigen::Vector2d g =
        -0.5 * true_m + (g_ok ? g_err : Eigen::Vector2d(garbage(rng), garbage(rng)));
    const Eigen::Vector2d f =
        0.5 * true_m + (f_ok ? f_err : Eigen::Vector2d(garbage(rng), garbage(rng)));
    const bool ok = f_ok && g_ok;
    cell.n_indirect_correct += ok;
    // Start y + g, end y + f: displacement f - g, start shifted off the centre.
    if (ok || include_wrong) cell.candidates.push_back({y + g, y + f, false});
  }
  return cell;
}

struct SegCase {
  bool has_direct;
  int n_b;
  double p;
};

class LemmaTest : public ::testing::TestWithParam<SegCase> {};

TEST_P(LemmaTest, Lemma1ExistenceMatchesSimulation) {
  const SegCase c = GetParam();
  std::mt19937_64 rng(1);
  const int trials = 200000;
  int exists = 0;
  for (int i = 0; i < trials; ++i) {
    const McCell cell = SimulateCell(rng, c.has_direct, c.n_b, c.p, {3, -1}, false);
    exists += cell.n_direct_correct + cell.n_indirect_correct > 0;
  }
  const double p_hat = static_cast<double>(exists) / trials;
  const double p = ImvExistenceProbability(c.has_direct, c.n_b, c.p);
  // Binomial standard error <= 0.0012 at 200k trials: 5 sigma.
  EXPECT_NEAR(p_hat, p, 0.006) << "lemma " << p << " simulation " << p_hat;
}

TEST_P(LemmaTest, Lemma2VarianceMatchesSimulationWithKnownImvs) {
  const SegCase c = GetParam();
  std::mt19937_64 rng(2);
  MergeOptions no_gate;
  no_gate.gate_sigmas = 1e9;  // the paper's assumption: the IMV set is known
  const Eigen::Vector2d true_m(3, -1);
  double sum_x = 0, sum_y = 0, sum_xx = 0, sum_yy = 0;
  int n = 0;
  for (int i = 0; i < 200000; ++i) {
    const McCell cell = SimulateCell(rng, c.has_direct, c.n_b, c.p, true_m, false);
    const auto merged = MergeCell(cell.candidates, kSigma, no_gate);
    ASSERT_EQ(merged.has_value(), !cell.candidates.empty());
    if (!merged) continue;
    EXPECT_DOUBLE_EQ(merged->variance_px2,
                     MergedVariance(cell.n_direct_correct, cell.n_indirect_correct, kSigma));
    const Eigen::Vector2d e = merged->earlier_px - merged->later_px - true_m;
    sum_x += e.x();
    sum_y += e.y();
    sum_xx += e.x() * e.x();
    sum_yy += e.y() * e.y();
    ++n;
  }
  const double expected = ExpectedMergedVariance(c.has_direct, c.n_b, c.p, kSigma);
  EXPECT_NEAR(sum_x / n, 0.0, 0.003);  // zero mean
  EXPECT_NEAR(sum_y / n, 0.0, 0.003);
  // Relative standard error of a variance estimate from >= 100k samples of a
  // mixture is ~1%: 4 % tolerance.
  EXPECT_NEAR(sum_xx / n / expected, 1.0, 0.04) << "expected " << expected;
  EXPECT_NEAR(sum_yy / n / expected, 1.0, 0.04);
}

INSTANTIATE_TEST_SUITE_P(Segments, LemmaTest,
                         ::testing::Values(SegCase{true, 3, 0.6}, SegCase{true, 3, 0.8},
                                           SegCase{false, 3, 0.8}, SegCase{true, 2, 0.9},
                                           SegCase{false, 1, 0.7}),
                         [](const auto& info) {
                           return std::string(info.param.has_direct ? "direct" : "nodirect") +
                                  "_nb" + std::to_string(info.param.n_b) + "_p" +
                                  std::to_string(static_cast<int>(info.param.p * 100));
                         });

// With wrong matches mixed in (every cell with at least three candidates),
// the consensus gate must keep wrong merges rare and the merged error at
// Lemma 2's level for the cells it accepts (those with >= 2 IMVs).
class GatingTest : public ::testing::TestWithParam<SegCase> {};

TEST_P(GatingTest, KeepsTheMergedErrorAtLemma2WithWrongMatches) {
  const SegCase c = GetParam();
  ASSERT_GE(c.n_b + (c.has_direct ? 1 : 0), 3);
  std::mt19937_64 rng(3);
  const Eigen::Vector2d true_m(3, -1);
  double sum_sq = 0;
  int merged_cells = 0, wrong_merges = 0, good = 0, two_imv_cells = 0, two_imv_merged = 0;
  for (int i = 0; i < 100000; ++i) {
    const McCell cell = SimulateCell(rng, c.has_direct, c.n_b, c.p, true_m, true);
    const auto merged = MergeCell(cell.candidates, kSigma, MergeOptions{});
    const int imvs = cell.n_direct_correct + cell.n_indirect_correct;
    if (imvs >= 2) {
      ++two_imv_cells;
      two_imv_merged += merged.has_value();
    }
    if (!merged) continue;
    ++merged_cells;
    const Eigen::Vector2d e = merged->earlier_px - merged->later_px - true_m;
    if (e.norm() > 1.5) {  // >= 4 sigma of any merged IMV set: not an IMV merge
      ++wrong_merges;
      continue;
    }
    sum_sq += 0.5 * e.squaredNorm();
    ++good;
  }
  // A wrong merge needs two wrong matches to agree (within ~2 px in a 32 px
  // square: ~1.2 % a pair) while the IMVs do not: a few per cent at most.
  EXPECT_LT(wrong_merges, 0.03 * merged_cells);
  // Two agreeing IMVs always win the consensus.
  EXPECT_GT(two_imv_merged, 0.99 * two_imv_cells);
  const double expected = ExpectedMergedVariance(c.has_direct, c.n_b, c.p, kSigma, 2);
  // Admitted wrong matches near the truth widen it a little: 15 %.
  EXPECT_NEAR(sum_sq / good / expected, 1.0, 0.15) << "expected " << expected;
}

INSTANTIATE_TEST_SUITE_P(Segments, GatingTest,
                         ::testing::Values(SegCase{true, 3, 0.6}, SegCase{true, 3, 0.8},
                                           SegCase{false, 3, 0.8}, SegCase{true, 2, 0.9}));

TEST(MergeTest, VarianceAndProbabilityClosedForms) {
  EXPECT_DOUBLE_EQ(MergedVariance(1, 0, kSigma), kSigma * kSigma);
  EXPECT_DOUBLE_EQ(MergedVariance(0, 1, kSigma), 2 * kSigma * kSigma);
  EXPECT_DOUBLE_EQ(MergedVariance(1, 3, kSigma), 2 * kSigma * kSigma / 5);
  EXPECT_TRUE(std::isinf(MergedVariance(0, 0, kSigma)));
  EXPECT_NEAR(ImvExistenceProbability(true, 3, 0.6), 1 - 0.4 * std::pow(1 - 0.36, 3), 1e-12);
  EXPECT_NEAR(ImvExistenceProbability(false, 3, 0.6), 1 - std::pow(1 - 0.36, 3), 1e-12);
  // Certain matches: every MV merged, variance 2 s^2 / (2 + n_b).
  EXPECT_NEAR(ExpectedMergedVariance(true, 3, 1.0, kSigma), MergedVariance(1, 3, kSigma), 1e-12);
}

TEST(MergeTest, WeightedStartEndMergeIsExactForAffineMotion) {
  // earlier = A later + b for every correspondence: the merged pair must obey it too,
  // although its candidates start at different points of the cell.
  Eigen::Matrix2d a;
  a << 1.3, 0.1, -0.05, 1.25;  // near-road scaling over a segment
  const Eigen::Vector2d b(-4, 7);
  std::vector<MvCandidate> cands;
  cands.push_back({{100, 100}, a * Eigen::Vector2d(100, 100) + b, true});
  for (const Eigen::Vector2d& s :
       {Eigen::Vector2d(95, 97), Eigen::Vector2d(104, 103), Eigen::Vector2d(99, 106)}) {
    cands.push_back({s, a * s + b, false});
  }
  MergeOptions wide;
  wide.gate_min_px = 100;
  const auto merged = MergeCell(cands, kSigma, wide);
  ASSERT_TRUE(merged);
  EXPECT_EQ(merged->n_direct, 1);
  EXPECT_EQ(merged->n_indirect, 3);
  EXPECT_LT((merged->earlier_px - (a * merged->later_px + b)).norm(), 1e-9);
  // Filing the displacements at the centre instead (the paper's way) is off by pixels here.
  Eigen::Vector2d mean_disp = Eigen::Vector2d::Zero();
  for (const auto& c : cands) mean_disp += (c.direct ? 2 : 1) * (c.earlier_px - c.later_px);
  mean_disp /= 5;
  EXPECT_GT((Eigen::Vector2d(100, 100) + mean_disp - (a * Eigen::Vector2d(100, 100) + b)).norm(),
            0.3);
}

// H.264 splits a near-road macroblock into partitions whose vectors differ
// by the flow's change between them; the gate allows that change
// (gate_flow_gradient_per_px) but not a jump between two surfaces.
TEST(MergeTest, FlowGradientGateKeepsPartitionsOfOneSurfaceAndRejectsMixedCells) {
  // The road at 10 fps, 70 km/h, ~150 rows below the horizon: the
  // displacement (earlier - later) grows 0.2 px per px across and 0.4 px per
  // px down the image around 40 px.
  const Eigen::Vector2d centre(600, 330), d0(6, 40);
  Eigen::Matrix2d gradient;
  gradient << 0.2, 0.0, 0.0, 0.4;
  std::vector<MvCandidate> partitions;
  for (const Eigen::Vector2d& offset : {Eigen::Vector2d(-4, -4), Eigen::Vector2d(4, -4),
                                        Eigen::Vector2d(-4, 4), Eigen::Vector2d(4, 4)}) {
    const Eigen::Vector2d later = centre + offset;
    partitions.push_back({later, later + d0 + gradient * offset, true});
  }
  MergeOptions positions_ignored;
  positions_ignored.gate_flow_gradient_per_px = 0.0;
  EXPECT_FALSE(MergeCell(partitions, kSigma, positions_ignored))
      << "8 px apart, the partitions differ by 1.6-3.6 px: no two agree without the gradient";
  MergeOptions with_gradient;
  with_gradient.gate_flow_gradient_per_px = 0.02;
  const auto merged = MergeCell(partitions, kSigma, with_gradient);
  ASSERT_TRUE(merged);
  EXPECT_EQ(merged->n_direct, 4);
  // Start and end points merged: exact for the affine field.
  EXPECT_LT((merged->earlier_px - (merged->later_px + d0 + gradient * (merged->later_px - centre)))
                .norm(),
            1e-9);
  // A facade's block beside the sky's, 8 px apart: 10 px against 3 px is a
  // jump, not a gradient (allowed: 1.41 + 0.02 * 8 * 3 = 1.89 px).
  const std::vector<MvCandidate> mixed = {{{100, 100}, {110, 100}, true},
                                          {{108, 100}, {111, 100}, true}};
  EXPECT_FALSE(MergeCell(mixed, kSigma, with_gradient));
  // An indirect candidate gets no allowance (its later point moves with a
  // wrong g): 8 px from a direct one, 2.5 px off at 40 px is a disagreement
  // (allowed 1.73 px; with the allowance it would be 8.1 px).
  const std::vector<MvCandidate> direct_and_indirect = {{{100, 100}, {140, 100}, true},
                                                        {{108, 100}, {150.5, 100}, false}};
  EXPECT_FALSE(MergeCell(direct_and_indirect, kSigma, with_gradient));
  // Candidates at the same place get no allowance: a wrong match 3 px off
  // still loses against two that agree.
  const std::vector<MvCandidate> same_place = {{{100, 100}, {140, 100}, true},
                                               {{100, 100}, {140.2, 100}, false},
                                               {{100, 100}, {143, 100}, false}};
  const auto kept = MergeCell(same_place, kSigma, with_gradient);
  ASSERT_TRUE(kept);
  EXPECT_EQ(kept->n_direct + kept->n_indirect, 2);
}

TEST(MergeTest, ConsensusRejectsAnOutlierAndAmbiguousCells) {
  std::vector<MvCandidate> cands = {{{0, 0}, {2, 0}, true},
                                    {{0, 0}, {2.1, 0.1}, false},
                                    {{0, 0}, {1.9, -0.1}, false},
                                    {{0, 0}, {-9, 5}, false}};
  const auto merged = MergeCell(cands, kSigma, MergeOptions{});
  ASSERT_TRUE(merged);
  EXPECT_EQ(merged->n_direct, 1);
  EXPECT_EQ(merged->n_indirect, 2);
  EXPECT_NEAR(merged->earlier_px.x(), 2.0, 1e-9);
  EXPECT_FALSE(MergeCell({}, kSigma, MergeOptions{}).has_value());
  // Three candidates, no two agreeing: nothing to merge.
  EXPECT_FALSE(
      MergeCell({{{0, 0}, {2, 0}, true}, {{0, 0}, {8, 0}, false}, {{0, 0}, {-5, 3}, false}}, kSigma,
                MergeOptions{})
          .has_value());
  // A lone candidate stands.
  EXPECT_TRUE(MergeCell({{{0, 0}, {2, 0}, false}}, kSigma, MergeOptions{}).has_value());
}

// Frame records of a pure translation by v px per frame, as the MV reader yields them.
FrameRecord Frame(int64_t index, PictureType type, int64_t prev, int64_t next, double vx,
                  bool with_mvs = true) {
  FrameRecord f;
  f.index = index;
  f.timestamp_s = index / 30.0;
  f.type = type;
  f.prev_anchor_index = prev;
  f.next_anchor_index = next;
  if (!with_mvs || type == PictureType::kI) return f;
  for (int row = 0; row < 4; ++row) {
    for (int col = 0; col < 4; ++col) {
      MotionVector mv;
      mv.x_px = 16 * col + 7.5f;
      mv.y_px = 16 * row + 7.5f;
      mv.dx_px = static_cast<float>(-(index - prev) * vx);  // past: against the motion
      f.mvs.push_back(mv);
      if (type == PictureType::kB) {
        mv.direction = RefDirection::kFuture;
        mv.dx_px = static_cast<float>((next - index) * vx);
        f.mvs.push_back(mv);
      }
    }
  }
  return f;
}

TEST(SegmentMergerTest, AssemblesIpPpAndPiSegments) {
  SegmentMerger merger(64, 64, kSigma);
  const double v = 0.5;
  EXPECT_FALSE(merger.Push(Frame(0, PictureType::kI, -1, -1, v)));
  for (int b = 1; b <= 3; ++b) EXPECT_FALSE(merger.Push(Frame(b, PictureType::kB, 0, 4, v)));
  auto ip = merger.Push(Frame(4, PictureType::kP, 0, -1, v));
  ASSERT_TRUE(ip);
  EXPECT_EQ(ip->type, SegmentType::kIP);
  EXPECT_EQ(ip->n_b, 3);
  EXPECT_EQ(ip->earlier_index, 0);
  EXPECT_EQ(ip->later_index, 4);
  EXPECT_EQ(ip->mb_cols, 4);
  EXPECT_EQ(ip->correspondences.size(), 16u);
  for (const Correspondence& c : ip->correspondences) {
    EXPECT_EQ(c.n_direct, 1);
    EXPECT_EQ(c.n_indirect, 3);  // one bi-predicted block per B frame
    EXPECT_NEAR((c.x_earlier_px - c.x_later_px).x(), -4 * v, 1e-6);
    EXPECT_DOUBLE_EQ(c.variance_px2, MergedVariance(c.n_direct, c.n_indirect, kSigma));
  }
  for (int b = 5; b <= 7; ++b) merger.Push(Frame(b, PictureType::kB, 4, 8, v));
  auto pp = merger.Push(Frame(8, PictureType::kP, 4, -1, v));
  ASSERT_TRUE(pp);
  EXPECT_EQ(pp->type, SegmentType::kPP);
  for (int b = 9; b <= 11; ++b) merger.Push(Frame(b, PictureType::kB, 8, 12, v));
  auto pi = merger.Push(Frame(12, PictureType::kI, 8, -1, v));
  ASSERT_TRUE(pi);
  EXPECT_EQ(pi->type, SegmentType::kPI);
  for (const Correspondence& c : pi->correspondences) {
    EXPECT_EQ(c.n_direct, 0);
    EXPECT_GE(c.n_indirect, 1);
    EXPECT_NEAR((c.x_earlier_px - c.x_later_px).x(), -4 * v, 1e-6);
  }
}

// The texture gate: cells whose block in the later anchor is flat give no
// correspondence, whichever candidates (direct or indirect) were filed there;
// an anchor without textures (a reader told not to compute them) is not gated.
TEST(SegmentMergerTest, TextureGateDropsFlatCellsOfTheLaterAnchor) {
  const double v = 0.5;
  const MergeOptions options;
  ASSERT_GT(options.min_mb_texture, 0.0);
  FrameRecord later = Frame(4, PictureType::kP, 0, -1, v);
  later.mb_texture.assign(16, static_cast<float>(10 * options.min_mb_texture));
  for (int cell : {0, 5, 15}) {
    later.mb_texture[cell] = static_cast<float>(0.9 * options.min_mb_texture);
  }
  for (const bool textured : {true, false}) {
    SegmentMerger merger(64, 64, kSigma, options);
    merger.Push(Frame(0, PictureType::kI, -1, -1, v));
    for (int b = 1; b <= 3; ++b) merger.Push(Frame(b, PictureType::kB, 0, 4, v));
    FrameRecord anchor = later;
    if (!textured) anchor.mb_texture.clear();
    const auto pair = merger.Push(anchor);
    ASSERT_TRUE(pair);
    std::vector<int> cells;
    for (const Correspondence& c : pair->correspondences) cells.push_back(c.mb_index);
    EXPECT_EQ(cells.size(), textured ? 13u : 16u);
    for (int flat : {0, 5, 15}) {
      EXPECT_EQ(std::count(cells.begin(), cells.end(), flat), textured ? 0 : 1) << flat;
    }
  }
  MergeOptions off = options;
  off.min_mb_texture = 0.0;   // the gate off: every cell
  off.min_pair_span_s = 0.0;  // the one-frame P pair is emitted, not chained
  SegmentMerger merger(64, 64, kSigma, off);
  merger.Push(Frame(0, PictureType::kI, -1, -1, v));
  FrameRecord p1 = Frame(1, PictureType::kP, 0, -1, v);
  p1.mb_texture = later.mb_texture;
  const auto pair = merger.Push(p1);
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->correspondences.size(), 16u);
}

// ExtendChain refuses a pair whose segment had B frames (its next segment
// would not compose onto it); a handed-back one-frame P pair followed by a
// B-frame segment: the segment's pair starts at the handed-back pair's
// earlier anchor, without vectors (they end at the anchor between).
TEST(SegmentMergerTest, ExtendChainRefusesBFramePairsAndKeepsPairsContiguousAfterOne) {
  MergeOptions unchained;
  unchained.min_pair_span_s = 0.0;  // one-frame P pairs, extended only when handed back
  SegmentMerger merger(64, 64, kSigma, unchained);
  const double v = 0.5;
  merger.Push(Frame(0, PictureType::kI, -1, -1, v));
  for (int b = 1; b <= 3; ++b) merger.Push(Frame(b, PictureType::kB, 0, 4, v));
  auto ip = merger.Push(Frame(4, PictureType::kP, 0, -1, v));
  ASSERT_TRUE(ip);
  EXPECT_FALSE(merger.ExtendChain(*ip));
  auto pp = merger.Push(Frame(5, PictureType::kP, 4, -1, v));
  ASSERT_TRUE(pp);
  EXPECT_EQ(pp->earlier_index, 4);
  EXPECT_TRUE(merger.ExtendChain(*pp));
  for (int b = 6; b <= 8; ++b) merger.Push(Frame(b, PictureType::kB, 5, 9, v));
  auto cut = merger.Push(Frame(9, PictureType::kP, 5, -1, v));
  ASSERT_TRUE(cut);
  EXPECT_EQ(cut->earlier_index, 4);
  EXPECT_EQ(cut->later_index, 9);
  EXPECT_EQ(cut->n_b, 4);
  EXPECT_EQ(cut->type, SegmentType::kPP);
  EXPECT_TRUE(cut->correspondences.empty());
  auto next = merger.Push(Frame(10, PictureType::kP, 9, -1, v));
  ASSERT_TRUE(next);
  EXPECT_EQ(next->earlier_index, 9);
  EXPECT_EQ(next->correspondences.size(), 16u);
}

TEST(SegmentMergerTest, IgnoresBFramesOfAnotherSegmentAndCorruptFrames) {
  SegmentMerger merger(64, 64, kSigma);
  merger.Push(Frame(0, PictureType::kI, -1, -1, 0.5));
  FrameRecord stray = Frame(1, PictureType::kB, -7, 4, 0.5);  // open-GOP leftover
  merger.Push(stray);
  FrameRecord broken = Frame(2, PictureType::kB, 0, 4, 0.5);
  broken.corrupt = true;
  merger.Push(broken);
  FrameRecord p = Frame(4, PictureType::kP, 0, -1, 0.5);
  auto pair = merger.Push(p);
  ASSERT_TRUE(pair);
  for (const Correspondence& c : pair->correspondences) EXPECT_EQ(c.n_indirect, 0);
}

}  // namespace
}  // namespace slapse

namespace slapse {
namespace {

// P frame of an IPPP stream whose content moves by x_prev = S x + b per frame
// (a zoom with a drift): each cell's vector is (S - I) x + b at its centre.
FrameRecord ZoomFrame(int64_t index, int cols, int rows, double s, const Eigen::Vector2d& b) {
  FrameRecord f;
  f.index = index;
  f.timestamp_s = index / 30.0;
  f.type = index == 0 ? PictureType::kI : PictureType::kP;
  f.prev_anchor_index = index - 1;
  if (index == 0) return f;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const Eigen::Vector2d x(16 * c + 7.5, 16 * r + 7.5);
      const Eigen::Vector2d d = (s - 1.0) * (x - Eigen::Vector2d(80, 60)) + b;
      MotionVector mv;
      mv.x_px = static_cast<float>(x.x());
      mv.y_px = static_cast<float>(x.y());
      mv.dx_px = static_cast<float>(d.x());
      mv.dy_px = static_cast<float>(d.y());
      f.mvs.push_back(mv);
    }
  }
  return f;
}

TEST(SegmentMergerTest, ChainsIpppVectorFieldsExactlyForAffineMotion) {
  const int cols = 10, rows = 8;  // 160 x 128
  const double s = 0.99;          // content grows 1 % a frame (driving forward)
  const Eigen::Vector2d b(0.7, -0.3), c(80, 60);
  MergeOptions chain4;
  chain4.min_pair_span_s = 3.5 / 30;  // ZoomFrame: 30 fps, so 4-frame chains
  SegmentMerger merger(160, 128, kSigma, chain4);
  std::vector<AnchorPair> pairs;
  for (int i = 0; i <= 8; ++i) {
    if (auto p = merger.Push(ZoomFrame(i, cols, rows, s, b))) pairs.push_back(*p);
  }
  // Gaps of 4 frames: (0 -> 4) and (4 -> 8).
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0].earlier_index, 0);
  EXPECT_EQ(pairs[0].later_index, 4);
  EXPECT_EQ(pairs[0].type, SegmentType::kIP);
  EXPECT_EQ(pairs[1].earlier_index, 4);
  EXPECT_EQ(pairs[1].type, SegmentType::kPP);
  for (const AnchorPair& pair : pairs) {
    EXPECT_GT(pair.correspondences.size(), 40u);
    for (const Correspondence& corr : pair.correspondences) {
      // Four steps of x -> s (x - c) + c + b.
      Eigen::Vector2d x = corr.x_later_px;
      for (int k = 0; k < 4; ++k) x = s * (x - c) + c + b;
      // Bilinear interpolation reproduces an affine field exactly inside the
      // grid; at the border the nearest cell stands in (off by the field's
      // change over half a cell, (1 - s) * 8 px per step).
      EXPECT_LT((corr.x_earlier_px - x).norm(), 0.1) << corr.x_later_px.transpose();
      EXPECT_NEAR(corr.variance_px2, 4 * kSigma * kSigma, 1e-12);  // four direct MVs
    }
  }
}

TEST(SegmentMergerTest, ChainingOffKeepsOneFrameSegmentsAndIFramesEndChainsContiguously) {
  MergeOptions off;
  off.min_pair_span_s = 0;
  SegmentMerger merger(160, 128, kSigma, off);
  int pairs = 0;
  for (int i = 0; i <= 4; ++i) {
    if (auto p = merger.Push(ZoomFrame(i, 10, 8, 0.99, {0, 0}))) {
      ++pairs;
      EXPECT_EQ(p->later_index - p->earlier_index, 1);
    }
  }
  EXPECT_EQ(pairs, 4);
  // With chaining, an I frame in the middle restarts the chain.
  MergeOptions on;
  on.min_pair_span_s = 3.5 / 30;
  SegmentMerger chained(160, 128, kSigma, on);
  std::vector<AnchorPair> out;
  for (int i = 0; i <= 9; ++i) {
    FrameRecord f = ZoomFrame(i, 10, 8, 0.99, {0, 0});
    if (i == 2) {
      f.type = PictureType::kI;
      f.mvs.clear();
    }
    if (auto p = chained.Push(f)) out.push_back(*p);
  }
  // The pair into the I frame carries no vectors (PI without B frames) and
  // ends the chain started at 0: it spans 0 -> 2, so that no frame falls
  // between two pairs (a pair 1 -> 2 would leave the motion 0 -> 1 out of
  // the trajectory while its time still passes); then 2 -> 6 is chained.
  ASSERT_GE(out.size(), 2u);
  EXPECT_EQ(out[0].earlier_index, 0);
  EXPECT_EQ(out[0].later_index, 2);
  EXPECT_EQ(out[0].earlier_timestamp_s, ZoomFrame(0, 10, 8, 0.99, {0, 0}).timestamp_s);
  EXPECT_EQ(out[0].n_b, 1);
  EXPECT_EQ(out[0].type, SegmentType::kII);  // from the I frame 0 to the I frame 2
  EXPECT_TRUE(out[0].correspondences.empty());
  EXPECT_EQ(out[1].earlier_index, 2);
  EXPECT_EQ(out[1].later_index, 6);
  for (size_t k = 1; k < out.size(); ++k) EXPECT_EQ(out[k].earlier_index, out[k - 1].later_index);
}

// The default chain span (MergeOptions::min_pair_span_s, in seconds): IPPP
// pairs of 2 frames at 30 fps, 3 at 60 fps, 1 at 10 fps, each starting where
// the last ended; at the stream's end Flush gives the open, shorter chain
// (its frames would otherwise get no pair), and nothing once none is open.
TEST(SegmentMergerTest, DefaultChainsSpanTheMinimumTimeAndFlushGivesTheRest) {
  const MergeOptions defaults;
  ASSERT_GT(defaults.min_pair_span_s, 1.0 / 30);
  ASSERT_LT(defaults.min_pair_span_s, 2.0 / 30);
  for (const auto& [fps, frames_per_pair] : {std::pair{30.0, 2}, {60.0, 3}, {10.0, 1}}) {
    SCOPED_TRACE(fps);
    SegmentMerger merger(160, 128, kSigma, defaults);
    const int last = 3 * frames_per_pair + 1;  // three whole pairs and one frame
    std::vector<AnchorPair> pairs;
    for (int i = 0; i <= last; ++i) {
      FrameRecord f = ZoomFrame(i, 10, 8, 0.99, {0.5, 0});
      f.timestamp_s = i / fps;
      if (auto p = merger.Push(f)) pairs.push_back(*p);
    }
    std::optional<AnchorPair> rest = merger.Flush();
    if (frames_per_pair == 1) {
      EXPECT_EQ(pairs.size(), static_cast<size_t>(last));
      EXPECT_FALSE(rest.has_value());
      continue;
    }
    ASSERT_EQ(pairs.size(), 3u);
    for (size_t k = 0; k < pairs.size(); ++k) {
      EXPECT_EQ(pairs[k].earlier_index, static_cast<int64_t>(k) * frames_per_pair);
      EXPECT_EQ(pairs[k].later_index - pairs[k].earlier_index, frames_per_pair);
      EXPECT_GE(pairs[k].later_timestamp_s - pairs[k].earlier_timestamp_s,
                defaults.min_pair_span_s);
      EXPECT_GT(pairs[k].correspondences.size(), 40u);
    }
    ASSERT_TRUE(rest.has_value());
    EXPECT_EQ(rest->earlier_index, pairs.back().later_index);
    EXPECT_EQ(rest->later_index, last);
    EXPECT_GT(rest->correspondences.size(), 40u);
    EXPECT_FALSE(merger.Flush().has_value());  // nothing is open any more
  }
}

// Timestamps that cannot be trusted never make a chain run away: equal
// timestamps (a stream without any) give one pair per P frame, and timestamps
// far too close together (wrong units) stop at kMaxChainFrames.
TEST(SegmentMergerTest, ChainsNeedIncreasingTimestampsAndStopAtTheFrameCap) {
  for (const double dt_s : {0.0, 1e-6}) {
    SCOPED_TRACE(dt_s);
    SegmentMerger merger(160, 128, kSigma);
    std::vector<AnchorPair> pairs;
    for (int i = 0; i <= 2 * MergeOptions::kMaxChainFrames; ++i) {
      FrameRecord f = ZoomFrame(i, 10, 8, 0.99, {0.5, 0});
      f.timestamp_s = i * dt_s;
      if (auto p = merger.Push(f)) pairs.push_back(*p);
    }
    const int64_t frames = dt_s > 0 ? MergeOptions::kMaxChainFrames : 1;
    ASSERT_EQ(pairs.size(), static_cast<size_t>(2 * MergeOptions::kMaxChainFrames / frames));
    for (const AnchorPair& p : pairs) EXPECT_EQ(p.later_index - p.earlier_index, frames);
  }
}

// A stream with adaptive B frames (x264's defaults): a chain still open when
// the first B frame comes is emitted then, as it is (the B segment's pair
// starts where it ends: no frame falls between two pairs), and once a B frame
// has been seen the stream's P-P segments are one pair each.
TEST(SegmentMergerTest, ABFrameClosesTheOpenChainAndEndsChaining) {
  SegmentMerger merger(64, 64, kSigma);  // default min_pair_span_s: 2 frames at 30 fps
  const double v = 0.5;
  std::vector<AnchorPair> pairs;
  auto push = [&](const FrameRecord& f) {
    if (auto p = merger.Push(f)) pairs.push_back(*p);
  };
  push(Frame(0, PictureType::kI, -1, -1, v));
  push(Frame(1, PictureType::kP, 0, -1, v));
  push(Frame(2, PictureType::kP, 1, -1, v));  // closes the chain 0 -> 2
  push(Frame(3, PictureType::kP, 2, -1, v));  // opens 2 -> 3
  ASSERT_EQ(pairs.size(), 1u);
  push(Frame(4, PictureType::kB, 3, 5, v));  // the open chain 2 -> 3 is emitted
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[1].earlier_index, 2);
  EXPECT_EQ(pairs[1].later_index, 3);
  EXPECT_FALSE(pairs[1].correspondences.empty());
  push(Frame(5, PictureType::kP, 3, -1, v));  // the B segment 3 -> 5
  push(Frame(6, PictureType::kP, 5, -1, v));  // a P-P segment: not chained any more
  push(Frame(7, PictureType::kP, 6, -1, v));
  ASSERT_EQ(pairs.size(), 5u);
  EXPECT_EQ(pairs[2].earlier_index, 3);
  EXPECT_EQ(pairs[2].later_index, 5);
  EXPECT_EQ(pairs[2].n_b, 1);
  for (size_t k = 3; k < pairs.size(); ++k) {
    EXPECT_EQ(pairs[k].later_index - pairs[k].earlier_index, 1);
  }
  for (size_t k = 1; k < pairs.size(); ++k)
    EXPECT_EQ(pairs[k].earlier_index, pairs[k - 1].later_index);
  EXPECT_FALSE(merger.Flush().has_value());
}

// ExtendChain (a pair too short to initialise on): with chaining off, the next
// P frame is composed onto the given pair and emitted at once, as exactly as
// a fixed chain; each further call extends it again; without a call the
// merger is back to one pair per frame; an I frame ends the extension, its
// pair starting at the extended pair's first anchor (the extended pair was
// handed back, so the anchor between has no pose yet).
TEST(SegmentMergerTest, ExtendChainGrowsTheLastPairFrameByFrame) {
  const double s = 0.99;
  const Eigen::Vector2d b(0.7, -0.3), c(80, 60);
  MergeOptions off;
  off.min_pair_span_s = 0;  // one pair per P frame unless extended
  SegmentMerger merger(160, 128, kSigma, off);
  std::optional<AnchorPair> pair;
  for (int i = 0; i <= 1; ++i) pair = merger.Push(ZoomFrame(i, 10, 8, s, b));
  ASSERT_TRUE(pair);
  ASSERT_EQ(pair->later_index, 1);
  for (int i = 2; i <= 4; ++i) {
    EXPECT_TRUE(merger.ExtendChain(*pair));
    pair = merger.Push(ZoomFrame(i, 10, 8, s, b));
    ASSERT_TRUE(pair) << i;
    EXPECT_EQ(pair->earlier_index, 0);
    EXPECT_EQ(pair->later_index, i);
    EXPECT_EQ(pair->type, SegmentType::kIP);
    EXPECT_GT(pair->correspondences.size(), 40u);
    for (const Correspondence& corr : pair->correspondences) {
      Eigen::Vector2d x = corr.x_later_px;
      for (int k = 0; k < i; ++k) x = s * (x - c) + c + b;
      EXPECT_LT((corr.x_earlier_px - x).norm(), 0.1) << i << ": " << corr.x_later_px.transpose();
      EXPECT_NEAR(corr.variance_px2, i * kSigma * kSigma, 1e-12);
    }
  }
  pair = merger.Push(ZoomFrame(5, 10, 8, s, b));  // no call: one frame again
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->earlier_index, 4);
  EXPECT_TRUE(merger.ExtendChain(*pair));
  FrameRecord i_frame = ZoomFrame(6, 10, 8, s, b);
  i_frame.type = PictureType::kI;
  i_frame.mvs.clear();
  pair = merger.Push(i_frame);
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->earlier_index, 4);
  EXPECT_EQ(pair->later_index, 6);
  EXPECT_EQ(pair->n_b, 1);
  EXPECT_EQ(pair->type, SegmentType::kPI);
  EXPECT_TRUE(pair->correspondences.empty());
  pair = merger.Push(ZoomFrame(7, 10, 8, s, b));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->earlier_index, 6);
  // A pair that does not end at the current anchor is ignored, and so is one
  // without correspondences.
  AnchorPair stale = *pair;
  stale.later_index = 3;
  EXPECT_FALSE(merger.ExtendChain(stale));
  pair = merger.Push(ZoomFrame(8, 10, 8, s, b));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->earlier_index, 7);
  AnchorPair empty = *pair;
  empty.correspondences.clear();
  EXPECT_FALSE(merger.ExtendChain(empty));
  pair = merger.Push(ZoomFrame(9, 10, 8, s, b));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->earlier_index, 8);
  EXPECT_FALSE(pair->correspondences.empty());
}

}  // namespace
}  // namespace slapse

namespace slapse {
namespace {

TEST(SegmentMergerTest, ChainsARealH264IpppStreamIntoFourFrameSegments) {
  const std::string path = testing::MakeTempDir("ippp_chain") + "/pan.ts";
  EncoderOptions eo;
  eo.codec = VideoCodec::kH264;
  eo.b_frames = 0;
  eo.gop_size = 60;
  eo.quality = 18;
  const double vx = 1.5, vy = -0.5;  // px per frame
  ASSERT_TRUE(testing::WritePan(path, eo, 17, vx, vy).ok());
  auto reader = MvReader::Open(path);
  ASSERT_TRUE(reader.ok());
  MergeOptions chain4;
  chain4.min_pair_span_s = 3.5 / 30;  // WritePan: 30 fps, so 4-frame chains
  SegmentMerger merger(320, 240, (*reader)->info().mv_sigma_px(), chain4);
  FrameRecord f;
  std::vector<AnchorPair> pairs;
  while ((*reader)->Next(&f).ok()) {
    if (auto p = merger.Push(f)) pairs.push_back(*p);
  }
  ASSERT_EQ(pairs.size(), 4u);  // 0-4, 4-8, 8-12, 12-16
  for (const AnchorPair& pair : pairs) {
    EXPECT_EQ(pair.later_index - pair.earlier_index, 4);
    std::vector<double> dx, dy;
    for (const Correspondence& c : pair.correspondences) {
      dx.push_back(c.x_earlier_px.x() - c.x_later_px.x());
      dy.push_back(c.x_earlier_px.y() - c.x_later_px.y());
    }
    ASSERT_GT(dx.size(), 100u);
    std::nth_element(dx.begin(), dx.begin() + dx.size() / 2, dx.end());
    std::nth_element(dy.begin(), dy.begin() + dy.size() / 2, dy.end());
    // Four frames of pan: the chained displacement is -4 v (quarter-pel steps).
    EXPECT_NEAR(dx[dx.size() / 2], -4 * vx, 0.25);
    EXPECT_NEAR(dy[dy.size() / 2], -4 * vy, 0.25);
  }
}

}  // namespace
}  // namespace slapse

namespace slapse {
namespace {

// One pyramid segment I0 b1 B2 b3 P4 (decoding order 0, 4, 2, 1, 3: B2 is a
// reference, the pyramid's top), its B frames marked as the reader marks a
// pyramid's; top_corrupt: B2 damaged (dropped by the merger). Returns the
// pair 0-4.
std::optional<AnchorPair> PushPyramidSegment(SegmentMerger* merger, bool top_corrupt) {
  merger->Push(Frame(0, PictureType::kI, -1, -1, 0.5));
  const int64_t coded[] = {0, 3, 2, 4};
  for (int b = 1; b <= 3; ++b) {
    FrameRecord f = Frame(b, PictureType::kB, 0, 4, 0.5);
    f.coded_index = coded[b];
    f.reference_certain = false;
    f.corrupt = top_corrupt && b == 2;
    merger->Push(f);
  }
  FrameRecord p = Frame(4, PictureType::kP, 0, -1, 0.5);
  p.coded_index = 1;
  return merger->Push(p);
}

// A pyramid whose top B frame was damaged (dropped): the first-decoded B
// left is not decoded right after the later anchor and may refer to the
// top, so no B frame is merged.
TEST(SegmentMergerTest, MergesNoBFrameWhenThePyramidTopIsMissing) {
  SegmentMerger merger(64, 64, kSigma);
  auto pair = PushPyramidSegment(&merger, true);
  ASSERT_TRUE(pair);
  EXPECT_TRUE(merger.b_pyramid_seen());
  ASSERT_EQ(pair->correspondences.size(), 16u);
  for (const Correspondence& c : pair->correspondences) EXPECT_EQ(c.n_indirect, 0);
}

// Under a B-pyramid only the first-decoded B frame of a segment (the
// pyramid's top, whose references are the anchors) gives indirect candidates;
// with pyramid_top_b off, none does.
TEST(SegmentMergerTest, MergesOnlyThePyramidTopOnceABPyramidShows) {
  for (const bool top_b : {true, false}) {
    MergeOptions options;
    options.pyramid_top_b = top_b;
    SegmentMerger merger(64, 64, kSigma, options);
    auto pair = PushPyramidSegment(&merger, false);
    ASSERT_TRUE(pair);
    EXPECT_TRUE(merger.b_pyramid_seen());
    ASSERT_EQ(pair->correspondences.size(), 16u);
    for (const Correspondence& c : pair->correspondences) {
      EXPECT_EQ(c.n_indirect, top_b ? 1 : 0) << "top_b " << top_b;
      EXPECT_EQ(c.n_direct, 1);
      // B2's past and future vectors compose to the anchors' 4 frames.
      EXPECT_NEAR(c.x_earlier_px.x() - c.x_later_px.x(), -4 * 0.5, 1e-9);
    }
  }
}

}  // namespace
}  // namespace slapse
