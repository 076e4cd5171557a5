// MvReader: decodes a compressed video with FFmpeg (flags2=+export_mvs) and
// yields, per frame in display order, the motion vectors the encoder chose.
//
//   auto reader = MvReader::Open("drive.ts");
//   if (!reader.ok()) { ... reader.status() ... }
//   FrameRecord frame;
//   Status s;
//   while ((s = (*reader)->Next(&frame)).ok()) { ... }
//   // s is OUT_OF_RANGE at a clean end of stream, DATA_LOSS if parts of the
//   // stream could not be decoded (the frames that did decode were yielded).
#pragma once

#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "core/common/status.h"
#include "core/mv/byte_source.h"
#include "core/mv/frame_record.h"
#include "core/mv/reencode.h"

struct AVFormatContext;
struct AVCodecContext;
struct AVIOContext;
struct AVPacket;
struct AVFrame;

namespace slapse {

struct MvReaderOptions {
  // Demuxer to force (e.g. "mpegts", "h264", "sdp"); empty = probe the input.
  std::string format;
  // Extra demuxer/protocol options, e.g. {"rtsp_transport", "tcp"}, {"timeout", "5000000"}.
  std::map<std::string, std::string> format_options;
  // Decoder threads; 1 keeps decoding deterministic and cheap for small frames.
  int decoder_threads = 1;
  // Also hand out each frame's decoded luma plane (for overlays; costs a copy).
  bool keep_luma = false;
  // With keep_luma: asked per frame whether its luma is wanted at all (e.g.
  // the server: only while someone looks at the overlays); unset = always.
  // A frame not wanted has no luma, and the reader copies nothing.
  std::function<bool()> luma_wanted;
  // Compute each anchor frame's per-macroblock texture (FrameRecord::
  // mb_texture), which merging uses to drop vectors of flat blocks
  // (MergeOptions::min_mb_texture). About 64 pixel reads per macroblock.
  bool mb_texture = true;
  // Bytes FFmpeg may read to identify the input and its streams
  // (AVFormatContext.probesize). The MPEG-TS demuxer also keeps this much of
  // a byte stream for seeking back while it probes, so a reader's I/O buffer
  // grows to it at the start (freed later). 0 = FFmpeg's default, 5 000 000.
  int64_t probe_bytes = 0;
  // Polled during blocking I/O; returning true aborts it (Next() then returns CANCELLED).
  std::function<bool()> interrupt;
  // A codec whose decoder exports no motion vectors (HEVC, VP9, AV1, MJPEG, ...)
  // is decoded and re-encoded in-process (core/mv/reencode.h) for its
  // vectors; false refuses such a stream with FAILED_PRECONDITION instead.
  bool reencode = true;
  ReencodeOptions reencode_options;
  // Network inputs: at the input's end (AVERROR_EOF), ask the source whether
  // it is still there (av_read_pause: RTSP sends PAUSE on its connection).
  // If it does not answer, the connection was lost and Next() ends
  // UNAVAILABLE ("the connection was lost ...") instead of OUT_OF_RANGE.
  // Why: FFmpeg's RTSP demuxer returns AVERROR_EOF both after an RTCP BYE on
  // every stream (a server that ended its stream) and when the server's TCP
  // connection closes (a killed camera); only the first still answers.
  bool check_source_at_end = false;
  // Decode only as much of each picture as the vectors and the frame's
  // error flags need. The vectors are parsed from the bitstream, so they come
  // out identical (mv_reader_test); only the pictures (the luma) differ.
  // Today: H.264 skips its in-loop deblocking filter (skip_loop_filter; the
  // luma is blockier). Not lowres for MPEG-1/2 / MPEG-4 Part 2, which would
  // cut more: FFmpeg's error resilience is off at lowres, so damaged frames
  // would no longer be flagged corrupt. Savings: docs/BENCHMARKS.md.
  bool reduced_decode = true;
};

// True if FFmpeg's decoder for this codec exports motion vectors.
bool CodecExportsMotionVectors(const std::string& codec_name);

class MvReader {
 public:
  // Opens a file path or URL (file:, rtsp:, rtp:, udp:, http:, ...).
  static StatusOr<std::unique_ptr<MvReader>> Open(const std::string& url,
                                                  const MvReaderOptions& options = {});
  // Reads the stream from `source` through a custom AVIOContext.
  static StatusOr<std::unique_ptr<MvReader>> Open(std::unique_ptr<ByteSource> source,
                                                  const MvReaderOptions& options = {});
  ~MvReader();
  MvReader(const MvReader&) = delete;
  MvReader& operator=(const MvReader&) = delete;

  // Fills `frame` with the next frame in display order. Returns OK with a
  // frame; OUT_OF_RANGE at a clean end of stream; DATA_LOSS at the end of a
  // stream that had undecodable parts; CANCELLED if interrupted; UNAVAILABLE
  // if the network input failed (or, with check_source_at_end, its source no
  // longer answers at the end).
  Status Next(FrameRecord* frame);

  const StreamInfo& info() const { return info_; }
  const ReadStats& stats() const { return stats_; }

 private:
  MvReader() = default;
  static StatusOr<std::unique_ptr<MvReader>> OpenImpl(std::unique_ptr<MvReader> reader,
                                                      const std::string& url,
                                                      const MvReaderOptions& options);
  static int InterruptTrampoline(void* opaque);
  static int ReadTrampoline(void* opaque, uint8_t* buf, int size);

  // Decodes until at least one frame is ready in `ready_` or the stream ends.
  Status Pump();
  // The demuxer returned `err` (< 0): the input is done; sets input_status_
  // (check_source_at_end asks the source here).
  void EndInput(int err);
  void Collect(AVFrame* frame);
  // A decoded frame of the input: its size checked against the stream's
  // (CheckFrameSize), then collected or re-encoded.
  void Take(AVFrame* frame);
  // Drains the re-encoder's frames into Collect.
  void DrainReencoder();
  // A frame whose size differs from the stream's first: with the aspect kept
  // its vectors are rescaled to the first size (the intrinsics' grid) and a
  // note says so; otherwise the stream ends with FAILED_PRECONDITION. False
  // when the frame must be dropped.
  bool CheckFrameSize(const AVFrame* frame);
  void Fail(Status status);
  // An MPEG-2 packet: looks for field pictures (StreamInfo::field_pictures)
  // and re-encodes the stream from its first frame on, or refuses it.
  void CheckPictureStructure(const AVPacket* packet);
  // Reads the input through the re-encoder from here on (Take); `why` for the notes.
  Status StartReencoding(const std::string& why);
  // The vectors of one decoded frame, in slapse's convention, into `rec`.
  void CollectVectors(const AVFrame* frame, FrameRecord* rec);
  void NoteError(const std::string& what);
  Status EndStatus() const;

  MvReaderOptions options_;
  std::unique_ptr<ByteSource> source_;
  AVFormatContext* fmt_ = nullptr;
  AVIOContext* avio_ = nullptr;
  AVCodecContext* dec_ = nullptr;
  AVPacket* pkt_ = nullptr;
  AVFrame* frame_ = nullptr;
  AVFrame* reencoded_ = nullptr;
  std::unique_ptr<Reencoder> reencoder_;
  // The first frame's size (the intrinsics'), and the current frame's scale to it.
  int base_width_px_ = 0, base_height_px_ = 0;
  int cur_width_px_ = 0, cur_height_px_ = 0;
  double scale_x_ = 1.0, scale_y_ = 1.0;
  int stream_index_ = -1;
  int64_t first_pts_ = INT64_MIN;
  double time_base_s_ = 0.0;

  StreamInfo info_;
  ReadStats stats_;
  bool input_done_ = false;    // demuxer reached the end (or failed)
  bool decoder_done_ = false;  // decoder fully drained
  Status input_status_;        // why the input ended, if not cleanly

  int64_t last_anchor_index_ = -1;
  int consecutive_b_ = 0;
  std::deque<FrameRecord> pending_;  // non-anchor frames waiting for their next anchor
  std::deque<FrameRecord> ready_;    // frames ready to hand out
};

}  // namespace slapse
