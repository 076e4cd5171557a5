// What the motion-vector reader yields: one FrameRecord per decoded frame, in
// display order, with the frame's motion vectors in slapse's pixel convention
// (core/common/camera.h: pixel centres on integers).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/common/mb_grid.h"

namespace slapse {

enum class PictureType : uint8_t { kUnknown = 0, kI, kP, kB };
// 'I', 'P', 'B' or '?'.
char PictureTypeChar(PictureType type);
inline bool IsAnchor(PictureType type) {
  return type == PictureType::kI || type == PictureType::kP;
}

// Which reference a vector points to. FFmpeg's `source` is the reference list:
// L0 (< 0) is the past anchor, L1 (> 0) the future anchor for MPEG-1/2/4 and
// for H.264 streams without B-pyramids or multiple references.
enum class RefDirection : int8_t { kPast = -1, kFuture = 1 };

struct MotionVector {
  // Block centre in the current frame, pixels (pixel-centre convention).
  float x_px = 0, y_px = 0;
  // Where the block's content sits in the reference frame, relative to the
  // block centre: reference position minus current position, in pixels, with
  // the codec's sub-pixel precision (FFmpeg motion_x / motion_scale).
  float dx_px = 0, dy_px = 0;
  uint8_t w_px = kMbSizePx, h_px = kMbSizePx;  // block size
  RefDirection direction = RefDirection::kPast;
};

struct FrameRecord {
  int64_t index = -1;        // display-order index of the decoded frame, from 0
  double timestamp_s = 0.0;  // presentation time relative to the first frame
  PictureType type = PictureType::kUnknown;
  // Display index of the nearest anchor (I/P) before this frame, -1 if none.
  // For P frames it is the frame their past vectors refer to.
  int64_t prev_anchor_index = -1;
  // B frames only: display index of the nearest anchor after this frame, the
  // reference of the future vectors; -1 if the stream ended before it.
  int64_t next_anchor_index = -1;
  // Decoder reported damage (concealed errors) in this frame; its vectors are suspect.
  bool corrupt = false;
  // Position in decoding order (FFmpeg's coded_picture_number), -1 if unknown.
  int64_t coded_index = -1;
  // False when the frame's vectors may use a reference other than the one
  // prev_anchor_index / next_anchor_index name: an H.264 P frame of a stream
  // whose SPS keeps more reference frames than its GOP needs
  // (StreamInfo::extra_references()), a B frame of a B-pyramid. FFmpeg does not
  // export a vector's reference index (docs/METHOD.md "Reference handling").
  bool reference_certain = true;
  std::vector<MotionVector> mvs;
  // Decoded luma plane (width x height, row-major), only when
  // MvReaderOptions::keep_luma is set; empty otherwise.
  std::vector<uint8_t> luma;
  // Anchor frames (I, P) when MvReaderOptions::mb_texture is set: each
  // macroblock's texture, MbTextureMinEigen (core/mv/mb_texture.h), row-major
  // over the MB grid, (levels / px)^2; empty otherwise (B frames, a frame
  // whose size differs from the stream's first).
  std::vector<float> mb_texture;

  // Display index of the anchor `mv` refers to: prev_anchor_index for a past
  // vector, next_anchor_index for a future one (-1 when there is none).
  int64_t ReferenceIndex(const MotionVector& mv) const {
    return mv.direction == RefDirection::kPast ? prev_anchor_index : next_anchor_index;
  }
};

// Facts about the stream known after opening (and refined while reading).
struct StreamInfo {
  std::string codec_name;   // FFmpeg decoder name, e.g. "mpeg2video", "h264"
  std::string format_name;  // demuxer, e.g. "mpegts"
  // The input's codec when it was re-encoded for its vectors (codec_name is
  // then the re-encoder's, kReencodeCodec); empty when read directly.
  std::string reencoded_from;
  int width_px = 0, height_px = 0;
  double fps = 0.0;            // nominal frame rate, 0 if unknown
  int mv_precision_denom = 2;  // 2 = half-pel, 4 = quarter-pel
  // Standard deviation of a correct MV's error (half the MV precision; docs/METHOD.md,
  // "MV reader"): 0.25 px for
  // half-pel codecs, 0.125 px for quarter-pel ones.
  double mv_sigma_px() const { return mv_precision_denom >= 4 ? 0.125 : 0.25; }
  int max_consecutive_b = 0;  // n_B seen so far: B frames between two anchors
  // False for codecs whose FFmpeg decoder exports stale B-frame vectors (MPEG-4
  // Part 2 and H.263 in FFmpeg 5.1 never write a B picture's motion table):
  // the reader then yields B frames without vectors rather than garbage.
  bool b_frame_mvs = true;
  // Reference structures that break the "nearest anchor" reading of MVs
  // (docs/METHOD.md, "MV merging"). FFmpeg does not export which reference a vector uses,
  // so these are detected and reported, never guessed:
  //  - b_pyramid: some B frame is decoded before a B frame shown earlier
  //    between the same anchors, i.e. B frames serve as references; their
  //    vectors may point to another B frame instead of an anchor.
  //  - max_ref_frames: the decoder's reference count (H.264 SPS
  //    num_ref_frames; 1 for MPEG).
  bool b_pyramid = false;
  int max_ref_frames = 1;
  // Some frame was coded as interlaced (AVFrame.interlaced_frame; MPEG-2:
  // progressive_frame = 0). For MPEG-2 (docs/METHOD.md, "Interlaced MPEG-2")
  // field-predicted vectors are dropped (ReadStats::field_mvs_dropped) and
  // field pictures re-encoded; other codecs' interlaced coding is not handled.
  bool interlaced = false;
  // MPEG-2 field pictures (each field coded as a picture of its own) were
  // seen; FFmpeg exports their vectors without their reference field, so the
  // stream is re-encoded (reencoded_from "mpeg2video") or refused.
  bool field_pictures = false;
  // The stream keeps more references than its anchors need (one for IPPP,
  // two with B frames, one more for a B-pyramid): a vector may point to an
  // older frame than the anchor the merger assumes.
  bool extra_references() const {
    return max_ref_frames > (max_consecutive_b > 0 ? 2 : 1) + (b_pyramid ? 1 : 0);
  }
};

// Counters the reader keeps while decoding; errors here end the stream with DATA_LOSS.
struct ReadStats {
  int64_t packets = 0;
  int64_t frames = 0;
  int64_t packet_errors = 0;   // packets the decoder rejected
  int64_t corrupt_frames = 0;  // frames decoded with concealed errors
  std::string first_error;     // human-readable description of the first error
  // Vectors not handed out because they cannot be read in frame pixels: an
  // interlaced MPEG-2 frame's field-predicted vectors (their reference field
  // is not exported), and vectors of macroblocks outside the picture (the
  // padded row of an interlaced MPEG-2 frame whose height is not a multiple of 32).
  int64_t field_mvs_dropped = 0;
  int64_t outside_mvs_dropped = 0;
  // CPU seconds (the reading thread's clock): decoding the input, and
  // re-encoding plus decoding the re-encoded frames (0 when not re-encoded).
  double decode_cpu_s = 0.0;
  double reencode_cpu_s = 0.0;
  // Changes in the stream that change how it is read, in order, e.g. a
  // resolution change whose vectors were rescaled. Never cleared.
  std::vector<std::string> notes;
};

}  // namespace slapse
