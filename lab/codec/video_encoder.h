// VideoEncoder: encodes BGR frames through libavcodec (mpeg2video, mpeg4,
// libx264) and muxes them with libavformat. Used by the simulator and by tests
// that need streams with known content.
#pragma once

#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "core/common/status.h"

struct AVCodecContext;
struct AVFormatContext;
struct AVFrame;
struct AVPacket;
struct AVStream;
struct SwsContext;

namespace slapse {

enum class VideoCodec { kMpeg2, kMpeg4, kH264 };
// "mpeg2", "mpeg4", "h264".
const char* VideoCodecName(VideoCodec codec);
StatusOr<VideoCodec> ParseVideoCodec(const std::string& name);

struct EncoderOptions {
  VideoCodec codec = VideoCodec::kMpeg2;
  // B frames between anchors (n_B). 3 gives MPEG-2's IBBBP; 0 gives IPPP.
  int b_frames = 3;
  // Frames from one I frame to the next.
  int gop_size = 12;
  double fps = 30.0;
  // Quality: MPEG-2/4 fixed quantiser (1 best .. 31), H.264 CRF (0 .. 51).
  int quality = 4;
  // MPEG-4 Part 2 only: quarter-pel motion vectors.
  bool mpeg4_qpel = false;
  // H.264 only: reference structure. The defaults give the plain GOP the
  // method assumes (B frames refer to their two anchors); cameras and
  // encoders often use B-pyramids and several references.
  bool h264_b_pyramid = false;
  int h264_refs = 1;
};

class VideoEncoder {
 public:
  // Opens `path` for writing; the container follows the extension
  // (.ts, .mpg, .mp4, .avi, .mkv, .h264/.m2v/.m4v for elementary streams).
  static StatusOr<std::unique_ptr<VideoEncoder>> Open(const std::string& path, int width_px,
                                                      int height_px, const EncoderOptions& options);
  ~VideoEncoder();
  VideoEncoder(const VideoEncoder&) = delete;
  VideoEncoder& operator=(const VideoEncoder&) = delete;

  // Encodes one 8-bit BGR frame of the opened size.
  Status Write(const cv::Mat& bgr);
  // Flushes the encoder and finalises the container. Idempotent.
  Status Finish();

  int64_t frames_written() const { return frames_; }

 private:
  VideoEncoder() = default;
  Status Drain(bool flush);

  std::string path_;
  AVFormatContext* mux_ = nullptr;
  AVCodecContext* enc_ = nullptr;
  AVStream* stream_ = nullptr;
  AVFrame* yuv_ = nullptr;
  AVPacket* pkt_ = nullptr;
  SwsContext* sws_ = nullptr;
  int64_t frames_ = 0;
  bool finished_ = false;
};

}  // namespace slapse
