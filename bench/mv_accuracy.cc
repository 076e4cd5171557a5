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
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

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
    const size_t good = std::count_if(e.begin(), e.end(), [](float v) { return v <= 2.0f; });
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

void PrintTable(const Table& t) {
  std::printf("  %-11s %-8s %8s  %8s  %8s  %9s\n", "kind", "flow px", "vectors", "<= 2 px",
              "median px", "length");
  for (int k = 0; k < kKinds; ++k) {
    for (int b = 0; b < kFlowBins; ++b) {
      t[k][b].Print(slapse::PlaneKindName(static_cast<slapse::PlaneKind>(k)), b);
    }
  }
}

// Adds one frame's plane-labelled vectors to the table.
void AddFrame(const slapse::GroundTruth& gt, const slapse::FrameRecord& frame, Table* table) {
  const int f = static_cast<int>(frame.index);
  for (const slapse::MotionVector& mv : frame.mvs) {
    const int64_t ref = mv.direction == slapse::RefDirection::kPast ? frame.prev_anchor_index
                                                                    : frame.next_anchor_index;
    if (ref < 0 || ref >= static_cast<int64_t>(gt.frames.size())) continue;
    const int label = gt.LabelAt(f, mv.x_px, mv.y_px);
    if (label < 0) continue;
    const Eigen::Vector2d x(mv.x_px, mv.y_px);
    Eigen::Vector2d x_true;
    if (!gt.TransferThroughPlane(label, f, static_cast<int>(ref), x, &x_true)) continue;
    const Eigen::Vector2d x_codec(mv.x_px + mv.dx_px, mv.y_px + mv.dy_px);
    const int kind = static_cast<int>(gt.planes[label].kind);
    const Eigen::Vector2d d_true = x_true - x;
    const double flow_px = d_true.norm();
    Cell& cell = (*table)[kind][FlowBin(flow_px)];
    cell.errors_px.push_back(static_cast<float>((x_codec - x_true).norm()));
    if (flow_px >= 1.0) {
      cell.length_bias.push_back(
          static_cast<float>((x_codec - x).dot(d_true) / (flow_px * flow_px) - 1.0));
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: mv_accuracy DRIVE_DIR [DRIVE_DIR ...]\n");
    return 2;
  }
  Table all{};
  for (int a = 1; a < argc; ++a) {
    const std::string dir = argv[a];
    auto gt = slapse::LoadGroundTruth(dir);
    auto reader = slapse::MvReader::Open(dir + "/drive.ts");
    if (!gt.ok() || !reader.ok()) {
      std::fprintf(stderr, "cannot read %s: %s\n", dir.c_str(),
                   (!gt.ok() ? gt.status() : reader.status()).ToString().c_str());
      return 1;
    }
    Table table{};
    slapse::FrameRecord frame;
    while ((*reader)->Next(&frame).ok()) {
      if (frame.corrupt || frame.index >= static_cast<int64_t>(gt->frames.size())) continue;
      AddFrame(*gt, frame, &table);
    }
    std::printf("%s\n", dir.c_str());
    PrintTable(table);
    Append(table, &all);
  }
  if (argc > 2) {
    std::printf("all\n");
    PrintTable(all);
  }
  return 0;
}
