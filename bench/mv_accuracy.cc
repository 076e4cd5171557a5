// mv_accuracy: how right the codec's motion vectors are, per surface kind and
// per true motion, against a simulated drive's ground truth. Each vector of a
// macroblock whose label is a plane (lab/gt/ground_truth.h, >= 90 % of its
// pixels on it) is compared with where the block centre's point on that
// plane truly is in the vector's reference frame (GroundTruth::
// TransferThroughPlane): the error is |x + d - x_true|, px. Rows: plane kind
// x the true displacement's length |x_true - x| (a B frame's vectors span one
// to three frames, a P frame's one or the anchor distance). A row says how
// many vectors there are, how many are within 2 px of the truth, the median
// error, and the median length bias: the vector's component along the true
// displacement over the true length, minus 1 (vectors whose true
// displacement is >= 1 px; negative: the codec's vectors are too short, which
// a plane's fitted distance and a road's height would inherit). Reading
// vectors only (no pipeline): what the method is given.
//   build/bench/mv_accuracy DRIVE_DIR [DRIVE_DIR ...]
// With --merged [--min-pair-span-s S], the anchor pairs' merged
// correspondences (core/merge, the pipeline's default MergeOptions: IPPP
// fields chained over MergeOptions::min_pair_span_s, S = 0 for one pair per
// P frame) are compared instead: each correspondence's earlier
// point against the later MB centre's point transferred through its plane
// into the earlier anchor; the flow bins are then the pair's true flow.
// With --span N, only the vectors whose reference is N frames from their own
// frame: a B frame's one-frame vectors against an IBBBP P frame's four-frame
// ones, where the codec's search stops following the near road
// (docs/TRAJECTORY.md "Session 28").
// With --texture, the anchor P frames' vectors by their block's texture
// (the merge's texture gate, MergeOptions::min_mb_texture): sky blocks and
// plane blocks per bin, and how right the plane blocks' vectors are.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/merge/mv_merge.h"
#include "core/mv/mv_reader.h"
#include "lab/gt/ground_truth.h"

namespace {

constexpr std::array<double, 8> kFlowEdgesPx = {0, 1, 2, 4, 8, 16, 32, 64};
constexpr int kFlowBins = static_cast<int>(kFlowEdgesPx.size());  // the last is open
constexpr int kKinds = 5;                                         // slapse::PlaneKind

int FlowBin(double flow_px) {
  int b = 0;
  while (b + 1 < kFlowBins && flow_px >= kFlowEdgesPx[b + 1]) ++b;
  return b;
}

// How many of the errors are within 2 px of the truth (the tables' "good").
size_t WithinTwoPx(const std::vector<float>& errors_px) {
  return std::count_if(errors_px.begin(), errors_px.end(), [](float v) { return v <= 2.0f; });
}

double Median(std::vector<float> v) {
  if (v.empty()) return std::nan("");
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

struct Cell {
  std::vector<float> errors_px;
  std::vector<float> length_bias;  // (d_codec . u_true) / |d_true| - 1
  void Print(const char* kind, int bin) const {
    if (errors_px.empty()) return;
    const std::vector<float>& e = errors_px;
    const size_t n = e.size();
    const double median = Median(e);
    const size_t good = WithinTwoPx(e);
    char range[32];
    if (bin + 1 < kFlowBins) {
      std::snprintf(range, sizeof range, "%g-%g", kFlowEdgesPx[bin], kFlowEdgesPx[bin + 1]);
    } else {
      std::snprintf(range, sizeof range, ">= %g", kFlowEdgesPx[bin]);
    }
    std::printf("  %-11s %-8s %8zu  %6.1f %%  %8.2f  %+8.1f %%\n", kind, range, n, 100.0 * good / n,
                median, 100.0 * Median(length_bias));
  }
};

using Table = std::array<std::array<Cell, kFlowBins>, kKinds>;

void Append(const Table& from, Table* to) {
  for (int k = 0; k < kKinds; ++k) {
    for (int b = 0; b < kFlowBins; ++b) {
      const Cell& c = from[k][b];
      Cell& d = (*to)[k][b];
      d.errors_px.insert(d.errors_px.end(), c.errors_px.begin(), c.errors_px.end());
      d.length_bias.insert(d.length_bias.end(), c.length_bias.begin(), c.length_bias.end());
    }
  }
}

// One line over the whole table: how many vectors, the share within 2 px,
// and the same for true displacements of 16 px and more (where a codec's
// motion search is most often wrong).
void PrintSummary(const Table& t) {
  size_t n = 0, good = 0, n_long = 0, good_long = 0;
  for (int k = 0; k < kKinds; ++k) {
    for (int b = 0; b < kFlowBins; ++b) {
      const std::vector<float>& e = t[k][b].errors_px;
      const size_t g = WithinTwoPx(e);
      n += e.size();
      good += g;
      if (kFlowEdgesPx[b] >= 16) {
        n_long += e.size();
        good_long += g;
      }
    }
  }
  std::printf(
      "  summary: %zu vectors, %.1f %% within 2 px; true flow >= 16 px: %.1f %% of them, "
      "%.1f %% within 2 px\n",
      n, n ? 100.0 * good / n : 0.0, n ? 100.0 * n_long / n : 0.0,
      n_long ? 100.0 * good_long / n_long : 0.0);
}

void PrintTable(const Table& t) {
  std::printf("  %-11s %-8s %8s  %8s  %8s  %9s\n", "kind", "flow px", "vectors", "<= 2 px",
              "median px", "length");
  for (int k = 0; k < kKinds; ++k) {
    for (int b = 0; b < kFlowBins; ++b) {
      t[k][b].Print(slapse::PlaneKindName(static_cast<slapse::PlaneKind>(k)), b);
    }
  }
  PrintSummary(t);
}

// Adds one cell's comparison of x_codec against the truth x_true (from x).
void AddVector(int kind, const Eigen::Vector2d& x, const Eigen::Vector2d& x_codec,
               const Eigen::Vector2d& x_true, Table* table) {
  const Eigen::Vector2d d_true = x_true - x;
  const double flow_px = d_true.norm();
  Cell& cell = (*table)[kind][FlowBin(flow_px)];
  cell.errors_px.push_back(static_cast<float>((x_codec - x_true).norm()));
  if (flow_px >= 1.0) {
    cell.length_bias.push_back(
        static_cast<float>((x_codec - x).dot(d_true) / (flow_px * flow_px) - 1.0));
  }
}

// Adds one anchor pair's plane-labelled merged correspondences to the table.
void AddPair(const slapse::GroundTruth& gt, const slapse::AnchorPair& pair, Table* table) {
  const int later = static_cast<int>(pair.later_index),
            earlier = static_cast<int>(pair.earlier_index);
  if (later >= static_cast<int>(gt.frames.size()) || earlier < 0) return;
  for (const slapse::Correspondence& c : pair.correspondences) {
    const int label = gt.LabelAt(later, c.x_later_px.x(), c.x_later_px.y());
    if (label < 0) continue;
    Eigen::Vector2d x_true;
    if (!gt.TransferThroughPlane(label, later, earlier, c.x_later_px, &x_true)) continue;
    AddVector(static_cast<int>(gt.planes[label].kind), c.x_later_px, c.x_earlier_px, x_true, table);
  }
}

// Adds one frame's plane-labelled vectors to the table (span > 0: only those
// whose reference is `span` frames away).
void AddFrame(const slapse::GroundTruth& gt, const slapse::FrameRecord& frame, int span,
              Table* table) {
  const int f = static_cast<int>(frame.index);
  for (const slapse::MotionVector& mv : frame.mvs) {
    const int64_t ref = frame.ReferenceIndex(mv);
    if (ref < 0 || ref >= static_cast<int64_t>(gt.frames.size())) continue;
    if (span > 0 && std::llabs(ref - frame.index) != span) continue;
    const int label = gt.LabelAt(f, mv.x_px, mv.y_px);
    if (label < 0) continue;
    const Eigen::Vector2d x(mv.x_px, mv.y_px);
    Eigen::Vector2d x_true;
    if (!gt.TransferThroughPlane(label, f, static_cast<int>(ref), x, &x_true)) continue;
    const Eigen::Vector2d x_codec(mv.x_px + mv.dx_px, mv.y_px + mv.dy_px);
    AddVector(static_cast<int>(gt.planes[label].kind), x, x_codec, x_true, table);
  }
}

// --texture: the anchor P frames' vectors by their block's texture
// (FrameRecord::mb_texture, lambda_min in (levels / px)^2): per bin, how many
// blocks see the sky (their vectors measure nothing), and of the
// plane-labelled ones how many are within 2 px of the truth.
constexpr std::array<double, 9> kTextureEdges = {0, 0.01, 0.03, 0.1, 0.3, 1, 3, 10, 30};
struct TextureBin {
  size_t sky = 0;
  std::vector<float> errors_px;
};
using TextureTable = std::array<TextureBin, kTextureEdges.size()>;

void AddTextureFrame(const slapse::GroundTruth& gt, const slapse::FrameRecord& frame,
                     TextureTable* table) {
  if (frame.type != slapse::PictureType::kP || frame.mb_texture.empty()) return;
  const int f = static_cast<int>(frame.index);
  const int cols = slapse::MbCount(gt.intrinsics.width_px);
  for (const slapse::MotionVector& mv : frame.mvs) {
    if (mv.direction != slapse::RefDirection::kPast || frame.prev_anchor_index < 0) continue;
    const int col = slapse::MbCellOf(mv.x_px), row = slapse::MbCellOf(mv.y_px);
    const double tex = frame.mb_texture[static_cast<size_t>(row) * cols + col];
    size_t b = 0;
    while (b + 1 < kTextureEdges.size() && tex >= kTextureEdges[b + 1]) ++b;
    const int label = gt.LabelAt(f, mv.x_px, mv.y_px);
    if (label == slapse::kMbSky) ++(*table)[b].sky;
    if (label < 0) continue;
    const Eigen::Vector2d x(mv.x_px, mv.y_px);
    Eigen::Vector2d x_true;
    if (!gt.TransferThroughPlane(label, f, static_cast<int>(frame.prev_anchor_index), x, &x_true)) {
      continue;
    }
    const Eigen::Vector2d x_codec(mv.x_px + mv.dx_px, mv.y_px + mv.dy_px);
    (*table)[b].errors_px.push_back(static_cast<float>((x_codec - x_true).norm()));
  }
}

void PrintTextureTable(const TextureTable& t) {
  std::printf("  %-12s %8s %8s %8s %9s\n", "texture", "sky", "planes", "<= 2 px", "median px");
  for (size_t b = 0; b < t.size(); ++b) {
    char range[32];
    if (b + 1 < t.size()) {
      std::snprintf(range, sizeof range, "%g-%g", kTextureEdges[b], kTextureEdges[b + 1]);
    } else {
      std::snprintf(range, sizeof range, ">= %g", kTextureEdges[b]);
    }
    const std::vector<float>& e = t[b].errors_px;
    std::printf("  %-12s %8zu %8zu %7.1f %% %9.2f\n", range, t[b].sky, e.size(),
                e.empty() ? 0.0 : 100.0 * WithinTwoPx(e) / e.size(), Median(e));
  }
}

}  // namespace

int main(int argc, char** argv) {
  bool merged = false, texture = false;
  int span = 0;
  slapse::MergeOptions merge;
  std::vector<std::string> dirs;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--merged") {
      merged = true;
    } else if (arg == "--span" && a + 1 < argc) {
      span = std::max(1, std::atoi(argv[++a]));
    } else if (arg == "--texture") {
      texture = true;
    } else if (arg == "--min-pair-span-s" && a + 1 < argc) {
      merge.min_pair_span_s = std::max(0.0, std::atof(argv[++a]));
    } else if (!arg.empty() && arg[0] != '-') {
      dirs.push_back(arg);
    } else {
      dirs.clear();
      break;
    }
  }
  if (dirs.empty()) {
    std::fprintf(
        stderr,
        "usage: mv_accuracy [--merged [--min-pair-span-s S] | --texture | --span N] DRIVE_DIR "
        "[DRIVE_DIR ...]\n");
    return 2;
  }
  Table all{};
  TextureTable all_texture{};
  for (const std::string& dir : dirs) {
    auto gt = slapse::LoadGroundTruth(dir);
    auto reader = slapse::MvReader::Open(dir + "/drive.ts");
    if (!gt.ok() || !reader.ok()) {
      std::fprintf(stderr, "cannot read %s: %s\n", dir.c_str(),
                   (!gt.ok() ? gt.status() : reader.status()).ToString().c_str());
      return 1;
    }
    Table table{};
    TextureTable texture_table{};
    slapse::SegmentMerger merger((*reader)->info().width_px, (*reader)->info().height_px,
                                 (*reader)->info().mv_sigma_px(), merge);
    slapse::FrameRecord frame;
    while ((*reader)->Next(&frame).ok()) {
      if (merged) {
        if (auto pair = merger.Push(frame); pair.has_value()) AddPair(*gt, *pair, &table);
        continue;
      }
      if (frame.corrupt || frame.index >= static_cast<int64_t>(gt->frames.size())) continue;
      if (texture) {
        AddTextureFrame(*gt, frame, &texture_table);
        continue;
      }
      AddFrame(*gt, frame, span, &table);
    }
    std::printf("%s\n", dir.c_str());
    if (texture) {
      PrintTextureTable(texture_table);
      for (size_t b = 0; b < all_texture.size(); ++b) {
        all_texture[b].sky += texture_table[b].sky;
        all_texture[b].errors_px.insert(all_texture[b].errors_px.end(),
                                        texture_table[b].errors_px.begin(),
                                        texture_table[b].errors_px.end());
      }
      continue;
    }
    PrintTable(table);
    Append(table, &all);
  }
  if (texture && dirs.size() > 1) {
    std::printf("all\n");
    PrintTextureTable(all_texture);
    return 0;
  }
  if (dirs.size() > 1) {
    std::printf("all\n");
    PrintTable(all);
  }
  return 0;
}
