// VideoEncoder: encodes BGR frames through libavcodec (mpeg2video, mpeg4,
// libx264, and for the re-encode path libx265, libvpx-vp9, mjpeg) and muxes
// them with libavformat. Used by the simulator and by tests that need streams
// with known content. EncoderPreset names camera-like settings.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"

struct AVCodecContext;
struct AVFormatContext;
struct AVFrame;
struct AVPacket;
struct AVStream;
struct SwsContext;

namespace slapse {

enum class VideoCodec { kMpeg2, kMpeg4, kH264, kHevc, kVp9, kMjpeg };
// "mpeg2", "mpeg4", "h264", "hevc", "vp9", "mjpeg".
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
  // H.264 only: x264's own defaults (preset medium: 3 B frames placed
  // adaptively, B-pyramid, 3 references, scene cuts, an I frame at most every
  // 250 frames) instead of the fixed GOP the other fields describe;
  // b_frames, gop_size, h264_b_pyramid and h264_refs are then not used.
  // What an encoder left at its defaults sends (issue 13's "x264 defaults").
  bool h264_x264_defaults = false;
  // H.264 only: profile ("baseline", "main", "high"); empty = x264's choice.
  std::string h264_profile;
  // H.264 only: a camera's bitrate instead of constant quality: average and
  // maximum bitrate (VBV, 1 s buffer) of this many bits per pixel and second
  // (6.5: 2 Mbit/s at 640x480, whatever the frame rate). 0: CRF `quality`.
  double h264_bits_per_pixel_s = 0.0;
  // MPEG-2 only: an interlaced camera's stream. Interlaced frame pictures,
  // top field first, each macroblock predicted and transformed by frame or by
  // field as the encoder finds cheaper (libavcodec's +ilme+ildct). The
  // simulator then renders each frame's bottom field half a frame after its
  // top field (lab/sim/simulate.h).
  bool interlaced = false;
};

// Camera-like encoder settings by name (issue 13; `slapse simulate --preset`):
//   mpeg2-ibbbp              MPEG-2, IBBBP, GOP 12, quantiser 4 (the paper's stream)
//   mpeg2-interlaced         the same as an interlaced camera codes it: interlaced
//                            frame pictures, top field first, field or frame
//                            prediction per macroblock (EncoderOptions::interlaced)
//   mpeg4-ibbbp              MPEG-4 Part 2, IBBBP, GOP 12, quantiser 4
//   h264-ippp                H.264 IPPP, GOP 12, CRF 20 (the simulator's old --gop IPPP)
//   h264-baseline-ippp-Ns    H.264 Baseline IPPP, one reference, an I frame every N s
//                            (N = 1, 2, 4, 10: IP cameras; 10 s: a "smart" GOP)
//   h264-baseline-ippp-2s-lowrate  the 2 s one at an IP camera's bitrate: 2 Mbit/s at
//                            640x480, scaled with the pixel count (6 Mbit/s at
//                            1280x720), VBV-capped (noisier vectors than CRF 20)
//   h264-main-bpyr-3ref      H.264 Main, 3 B frames, B-pyramid, 3 references, GOP 2 s
//   h264-high-bpyr-3ref      the same with High profile (x264's defaults for B frames)
//   h264-x264-defaults       x264 left at its defaults (preset medium, CRF 20): B frames
//                            placed adaptively (0-3), B-pyramid, 3 references, scene
//                            cuts, an I frame at most every 250 frames
//   hevc                     H.265 (libx265), x265's B frames and references, GOP 2 s
//   vp9, mjpeg               other codecs without exported vectors (re-encode path;
//                            MJPEG needs a .mkv or .avi container)
// `fps` sets the GOPs given in seconds.
StatusOr<EncoderOptions> EncoderPreset(const std::string& name, double fps);
// The names above, in that order (N expanded).
std::vector<std::string> EncoderPresetNames();

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
