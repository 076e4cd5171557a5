#include "server/frame_overlays.h"

#include <algorithm>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/viz/mv_overlay.h"
#include "core/viz/plane_overlay.h"

namespace slapse::server {
namespace {

int64_t SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// `picture` scaled down (area averaging) to at most `max_width_px` wide, as
// a PNG with the fastest compression (the pictures are mostly a photo: a
// higher level costs several times the time for a few per cent).
StatusOr<OverlayPng> Encode(const cv::Mat& picture, int max_width_px, int64_t frame_index,
                            int count) {
  cv::Mat scaled = picture;
  if (max_width_px > 0 && picture.cols > max_width_px) {
    const double f = static_cast<double>(max_width_px) / picture.cols;
    cv::resize(picture, scaled, cv::Size(), f, f, cv::INTER_AREA);
  }
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", scaled, bytes, {cv::IMWRITE_PNG_COMPRESSION, 1})) {
    return InternalError("could not encode the overlay as PNG");
  }
  OverlayPng out;
  out.png.assign(bytes.begin(), bytes.end());
  out.frame_index = frame_index;
  out.count = count;
  out.width_px = scaled.cols;
  out.height_px = scaled.rows;
  return out;
}

}  // namespace

StatusOr<OverlayKind> ParseOverlayKind(const std::string& text) {
  if (text == "mv") return OverlayKind::kMotionVectors;
  if (text == "planes") return OverlayKind::kPlanes;
  return InvalidArgumentError("query parameter 'kind' must be mv or planes, not '" + text + "'");
}

bool FrameOverlays::Wanted() const { return SteadyNowNs() < wanted_until_ns_.load(); }

void FrameOverlays::SetAnchor(FrameRecord frame, int width_px, int height_px) {
  auto luma = std::make_shared<const std::vector<uint8_t>>(std::move(frame.luma));
  frame.luma.clear();
  std::lock_guard<std::mutex> lock(mu_);
  width_px_ = width_px;
  height_px_ = height_px;
  latest_index_ = frame.index;
  latest_luma_ = luma;
  if (!frame.mvs.empty() || mv_frame_.index < 0) {
    mv_frame_ = std::move(frame);
    mv_luma_ = std::move(luma);
  }
}

void FrameOverlays::SetPlanes(int64_t earlier_index, int64_t later_index,
                              const std::vector<ExtractedPlane>& planes) {
  std::lock_guard<std::mutex> lock(mu_);
  planes_earlier_ = earlier_index;
  planes_later_ = later_index;
  planes_ = planes;
  planes_luma_ = later_index == latest_index_ ? latest_luma_ : nullptr;
}

void FrameOverlays::Clear() {
  std::lock_guard<std::mutex> lock(mu_);
  if (mv_frame_.index < 0 && planes_later_ < 0) return;
  mv_frame_ = FrameRecord();
  mv_luma_.reset();
  latest_index_ = -1;
  latest_luma_.reset();
  planes_earlier_ = planes_later_ = -1;
  planes_.clear();
  planes_luma_.reset();
  mv_cache_ = planes_cache_ = Cached();
}

StatusOr<OverlayPng> FrameOverlays::Png(OverlayKind kind, int max_width_px) {
  wanted_until_ns_ = SteadyNowNs() + std::chrono::nanoseconds(kWantedFor).count();
  const bool mv = kind == OverlayKind::kMotionVectors;
  // What to draw, copied under the lock (the luma is shared, not copied).
  FrameRecord frame;
  Luma luma;
  int64_t earlier = -1, later = -1;
  std::vector<ExtractedPlane> planes;
  int width = 0, height = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    const int64_t index = mv ? mv_frame_.index : planes_later_;
    if (index < 0) {
      return UnavailableError(
          "no frame kept yet: frames are kept only while the dashboard asks for them; the next "
          "anchor frame will be");
    }
    if (width_px_ <= 0 || height_px_ <= 0) {
      return UnavailableError("the stream's image size is not known yet");
    }
    const Cached& cached = mv ? mv_cache_ : planes_cache_;
    if (cached.frame_index == index && cached.max_width_px == max_width_px) return cached.png;
    width = width_px_;
    height = height_px_;
    if (mv) {
      frame.index = mv_frame_.index;
      frame.type = mv_frame_.type;
      frame.mvs = mv_frame_.mvs;
      luma = mv_luma_;
    } else {
      earlier = planes_earlier_;
      later = planes_later_;
      planes = planes_;
      luma = planes_luma_;
    }
  }
  static const std::vector<uint8_t> kNoLuma;
  const std::vector<uint8_t>& l = luma ? *luma : kNoLuma;
  if (mv) frame.luma = l;  // DrawMotionVectors reads the record's own
  const cv::Mat picture = mv ? DrawMotionVectors(frame, width, height)
                             : DrawPlanes(l, width, height, earlier, later, planes);
  auto png = Encode(picture, max_width_px, mv ? frame.index : later,
                    static_cast<int>(mv ? frame.mvs.size() : planes.size()));
  if (!png.ok()) return png.status();
  std::lock_guard<std::mutex> lock(mu_);
  Cached& cached = mv ? mv_cache_ : planes_cache_;
  if (png->frame_index >= cached.frame_index) cached = Cached{png->frame_index, max_width_px, *png};
  return png;
}

}  // namespace slapse::server
