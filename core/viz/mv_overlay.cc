#include "core/viz/mv_overlay.h"

#include <cstdio>
#include <utility>

#include <opencv2/imgproc.hpp>

namespace slapse {

cv::Mat DrawMotionVectors(const FrameRecord& frame, int width_px, int height_px,
                          const MvOverlayOptions& options) {
  cv::Mat gray(height_px, width_px, CV_8UC1, cv::Scalar(128));
  if (frame.luma.size() == static_cast<size_t>(width_px) * height_px) {
    cv::Mat(height_px, width_px, CV_8UC1, const_cast<uint8_t*>(frame.luma.data())).copyTo(gray);
  }
  cv::Mat out;
  cv::cvtColor(gray, out, cv::COLOR_GRAY2BGR);
  const cv::Scalar past(40, 40, 255), future(255, 120, 40);  // BGR: red, blue
  for (const MotionVector& mv : frame.mvs) {
    const cv::Point2d from(mv.x_px, mv.y_px);
    const cv::Point2d to(mv.x_px + options.arrow_scale * mv.dx_px,
                         mv.y_px + options.arrow_scale * mv.dy_px);
    const cv::Scalar& colour = mv.direction == RefDirection::kPast ? past : future;
    if (mv.dx_px == 0 && mv.dy_px == 0) {
      cv::circle(out, from, 1, colour, cv::FILLED, cv::LINE_AA);
    } else {
      cv::arrowedLine(out, from, to, colour, options.thickness_px, cv::LINE_AA, 0, 0.3);
    }
  }
  if (options.caption) {
    // Two short lines, so that they fit a 320-pixel-wide frame.
    char text[128];
    std::snprintf(text, sizeof(text), "frame %lld  %c  %zu MVs",
                  static_cast<long long>(frame.index), PictureTypeChar(frame.type),
                  frame.mvs.size());
    const char* key = "red: past, blue: future";
    for (const auto& [line, y] : {std::pair<const char*, int>{text, 20}, {key, 40}}) {
      cv::putText(out, line, cv::Point(8, y), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 3,
                  cv::LINE_AA);
      cv::putText(out, line, cv::Point(8, y), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                  cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    }
  }
  return out;
}

}  // namespace slapse
