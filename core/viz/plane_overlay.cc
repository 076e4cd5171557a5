#include "core/viz/plane_overlay.h"

#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "core/common/mb_grid.h"

namespace slapse {

cv::Scalar TrackColour(int track_id) {
  // Golden-angle hues: neighbouring ids get far-apart colours.
  const int hue = static_cast<int>(std::fmod(track_id * 137.508, 360.0) / 2.0);
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(hue, 230, 255)), bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  const cv::Vec3b c = bgr.at<cv::Vec3b>(0, 0);
  return cv::Scalar(c[0], c[1], c[2]);
}

cv::Mat DrawPlanes(const std::vector<uint8_t>& luma, int width_px, int height_px,
                   int64_t earlier_index, int64_t later_index,
                   const std::vector<ExtractedPlane>& planes) {
  cv::Mat gray(height_px, width_px, CV_8UC1, cv::Scalar(128));
  if (luma.size() == static_cast<size_t>(width_px) * height_px) {
    cv::Mat(height_px, width_px, CV_8UC1, const_cast<uint8_t*>(luma.data())).copyTo(gray);
  }
  cv::Mat out;
  cv::cvtColor(gray, out, cv::COLOR_GRAY2BGR);
  const int mb_cols = MbCount(width_px);
  for (const ExtractedPlane& plane : planes) {
    const cv::Scalar colour = TrackColour(plane.track_id);
    for (int cell : plane.mb_indices) {
      const Eigen::Vector2d x = MbCentreOfCell(cell % mb_cols, cell / mb_cols);
      cv::circle(out, cv::Point2d(x.x(), x.y()), 4, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
      cv::circle(out, cv::Point2d(x.x(), x.y()), 3, colour, cv::FILLED, cv::LINE_AA);
    }
  }
  char text[128];
  std::snprintf(text, sizeof(text), "anchors %lld -> %lld  %zu plane%s",
                static_cast<long long>(earlier_index), static_cast<long long>(later_index),
                planes.size(), planes.size() == 1 ? "" : "s");
  cv::putText(out, text, cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 3,
              cv::LINE_AA);
  cv::putText(out, text, cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255),
              1, cv::LINE_AA);
  return out;
}

}  // namespace slapse
