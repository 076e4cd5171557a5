// Fuzzes the motion-vector reader through its byte source: the input is a
// whole stream (any container FFmpeg probes from a non-seekable byte stream:
// MPEG-TS, PS, elementary MPEG-2 / MPEG-4 / H.264, ...) handed to
// MvReader::Open(MemoryByteSource) exactly as an upload reaches it; then
// demux + decode + MV export for at most kMaxFrames frames.
//
// Invariants checked beyond "no crash / leak / UB":
//  - frames come out in display order: index 0, 1, 2, ... with no gap;
//  - a frame's prev_anchor_index < index, a B frame's next_anchor_index is
//    -1 or > index, and only B frames have one;
//  - timestamps are finite; vectors are finite, with a non-zero block size;
//  - Next() keeps returning the same non-OK code once the stream ended.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

extern "C" {
#include <libavutil/log.h>
}

#include "core/mv/byte_source.h"
#include "core/mv/mv_reader.h"

namespace {

constexpr int kMaxFrames = 48;         // bounds the decode work per input
constexpr size_t kMaxInputBytes = 256 << 10;

void Check(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_mv_reader: invariant violated: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  av_log_set_level(AV_LOG_QUIET);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > kMaxInputBytes) return -1;  // keep it out of the corpus
  auto source = std::make_unique<slapse::MemoryByteSource>(
      std::string(reinterpret_cast<const char*>(data), size));
  auto reader = slapse::MvReader::Open(std::move(source));
  if (!reader.ok()) return 0;
  const slapse::StreamInfo& info = (*reader)->info();
  // Huge pictures (fuzzed dimensions) only cost time and memory.
  if (static_cast<int64_t>(info.width_px) * info.height_px > 1920 * 1088) return 0;
  slapse::FrameRecord frame;
  slapse::Status s;
  int64_t expected = 0;
  while (expected < kMaxFrames && (s = (*reader)->Next(&frame)).ok()) {
    Check(frame.index == expected, "frames out of display order or skipped");
    ++expected;
    Check(std::isfinite(frame.timestamp_s), "timestamp not finite");
    Check(frame.prev_anchor_index < frame.index, "prev_anchor_index >= index");
    if (frame.type == slapse::PictureType::kB) {
      Check(frame.next_anchor_index == -1 || frame.next_anchor_index > frame.index,
            "B frame's next anchor is not after it");
    } else {
      Check(frame.next_anchor_index == -1, "non-B frame has a next anchor");
    }
    for (const slapse::MotionVector& mv : frame.mvs) {
      Check(std::isfinite(mv.dx_px) && std::isfinite(mv.dy_px), "vector not finite");
      Check(mv.w_px > 0 && mv.h_px > 0, "empty block");
    }
  }
  if (!s.ok()) {
    Check((*reader)->Next(&frame).code() == s.code(), "end status changed on a second Next()");
  }
  return 0;
}
