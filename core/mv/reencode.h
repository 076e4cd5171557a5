// Reencoder: turns decoded frames of a codec whose FFmpeg decoder exports no
// motion vectors (HEVC, VP9, AV1, MJPEG, ...) into frames that carry them:
// each frame is encoded in-process with libavcodec's mpeg2video (IBBBP, a
// wide motion search; docs/METHOD.md "Re-encoding") and the packets are
// decoded again with export_mvs. Used by MvReader for every input kind.
//
//   auto re = Reencoder::Open(1280, 720, ReencodeOptions{});
//   (*re)->Send(decoded, decoded->best_effort_timestamp);  // any pixel format
//   while ((*re)->Receive(out) == 0) { ... out has MVs, out->pts = source pts ... }
//   (*re)->Send(nullptr, 0);  // flush; then Receive until AVERROR_EOF
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>

#include "core/common/status.h"

struct AVCodecContext;
struct AVFrame;
struct AVPacket;
struct SwsContext;

namespace slapse {

// The encoder's settings, chosen for motion-vector quality on the tuning
// drives (docs/METHOD.md "Re-encoding"; bench: docs/BENCHMARKS.md).
struct ReencodeOptions {
  // mpeg2video fixed quantiser, 1 (best) .. 31. 2: on the tuning drives
  // (HEVC CRF 23 sources) mean ATE 0.58 % of the distance against 0.83 %
  // with 4, at 2.2x instead of 2.0x the CPU of decoding the source
  // (docs/METHOD.md "Re-encoding").
  int quantiser = 2;
  // B frames between anchors: 3 gives IBBBP, the structure the merger was built for.
  int b_frames = 3;
  // Frames from one I frame to the next.
  int gop_size = 12;
  // Motion search: diamond size and predictors from the last frame (FFmpeg's
  // dia_size / last_pred; the defaults 1 / 0 miss the 20-40 px motion of a near road).
  int dia_size = 4;
  int last_pred = 3;

  Status Check() const;
};

// CPU seconds of the calling thread (CLOCK_THREAD_CPUTIME_ID): costs stay
// measurable on a loaded machine, where wall time counts other processes.
double ThreadCpuSeconds();

// Adds the calling thread's CPU time over a scope to `*total_s`.
class ScopedCpuTimer {
 public:
  explicit ScopedCpuTimer(double* total_s) : total_s_(total_s), t0_s_(ThreadCpuSeconds()) {}
  ~ScopedCpuTimer() { *total_s_ += ThreadCpuSeconds() - t0_s_; }
  ScopedCpuTimer(const ScopedCpuTimer&) = delete;
  ScopedCpuTimer& operator=(const ScopedCpuTimer&) = delete;

 private:
  double* total_s_;
  double t0_s_;
};

// Name of the encoder whose vectors a re-encoded stream carries.
inline constexpr const char* kReencodeCodec = "mpeg2video";

class Reencoder {
 public:
  // Frames sent must be width_px x height_px (any pixel format; they are
  // converted to 4:2:0 8 bit).
  static StatusOr<std::unique_ptr<Reencoder>> Open(int width_px, int height_px,
                                                   const ReencodeOptions& options);
  ~Reencoder();
  Reencoder(const Reencoder&) = delete;
  Reencoder& operator=(const Reencoder&) = delete;

  // Encodes `frame` (display order) with `source_pts` as the timestamp the
  // decoded copy will carry; nullptr flushes (source_pts ignored).
  Status Send(const AVFrame* frame, int64_t source_pts);
  // The next decoded frame of the re-encoded stream (display order, motion
  // vectors as side data, pts and best_effort_timestamp = the source pts):
  // 0, AVERROR(EAGAIN) until more frames are sent, AVERROR_EOF after a flush.
  int Receive(AVFrame* out);

  int width_px() const { return width_px_; }
  int height_px() const { return height_px_; }
  // CPU seconds spent converting, encoding and decoding (this thread's clock).
  double cpu_s() const { return cpu_s_; }
  int64_t frames_sent() const { return next_pts_; }

 private:
  Reencoder() = default;
  Status DrainEncoder();

  int width_px_ = 0, height_px_ = 0;
  AVCodecContext* enc_ = nullptr;
  AVCodecContext* dec_ = nullptr;
  AVFrame* yuv_ = nullptr;
  AVPacket* pkt_ = nullptr;
  SwsContext* sws_ = nullptr;
  std::deque<AVPacket*> packets_;          // encoded, not yet decoded
  std::map<int64_t, int64_t> source_pts_;  // encoder pts (frame counter) -> source pts
  int64_t next_pts_ = 0;
  bool flushing_ = false, decoder_flushed_ = false;
  double cpu_s_ = 0.0;
};

}  // namespace slapse
