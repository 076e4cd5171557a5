// map.png's plot: fitted to the drive (a far facade does not shrink it to a
// few pixels), with a scale bar.
#include "lab/viz/top_down_plot.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace slapse {
namespace {

// Columns of `img` that hold `colour` (BGR), as [first, last]; {-1, -1} if none.
std::pair<int, int> ColumnsOf(const cv::Mat& img, const cv::Vec3b& colour) {
  int first = -1, last = -1;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) {
      if (img.at<cv::Vec3b>(y, x) != colour) continue;
      first = first < 0 ? x : std::min(first, x);
      last = std::max(last, x);
    }
  }
  return {first, last};
}

TEST(TopDownPlot, FitsTheDriveNotTheWholeCity) {
  TopDownPlot plot;
  plot.AddPath({{0, 0}, {25, 1}, {50, 0}}, cv::Scalar(30, 30, 220), "drive", 2);
  plot.AddSegment({0, 5}, {50, 5}, cv::Scalar(190, 190, 190), 3);  // facade along the road
  plot.AddSegment({1000, 1000}, {1010, 1000}, cv::Scalar(190, 190, 190), 3);  // far away
  plot.AddPoints({{5000, -5000}}, cv::Scalar(0, 200, 0), 2);                  // an outlier point
  const cv::Mat img = plot.Render(400, 400, "t", "m");
  const auto [first, last] = ColumnsOf(img, cv::Vec3b(30, 30, 220));
  ASSERT_GE(first, 0);
  // The 50 m drive spans most of the 400 px width (it spanned ~18 px when the
  // far facade set the extent).
  EXPECT_GT(last - first, 250) << first << ".." << last;
}

TEST(TopDownPlot, ScaleBarIsOneGridStepLong) {
  TopDownPlot plot;
  plot.AddPath({{0, 0}, {100, 0}}, cv::Scalar(30, 30, 220), "drive", 2);
  const cv::Mat img = plot.Render(500, 300, "t", "m");
  // The bar: the run of black pixels on the row 14 px above the bottom from x = 12.
  const int row = img.rows - 14;
  int x = 12;
  while (x < img.cols && img.at<cv::Vec3b>(row, x) == cv::Vec3b(0, 0, 0)) ++x;
  const int bar_px = x - 12;
  // 100 m + 16 % margin over 480 px is ~4.1 px/m: a grid step of 10 or 20 m
  // is 41 or 83 px; no bar (0) or one across the plot fails.
  EXPECT_GT(bar_px, 30);
  EXPECT_LT(bar_px, 200);
}

}  // namespace
}  // namespace slapse
