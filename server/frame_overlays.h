// FrameOverlays: a session's latest anchor frame as pictures for the
// dashboard (GET /api/overlay, server/dashboard.h): its motion vectors as
// arrows over its luma (DrawMotionVectors), and the planes extracted on the
// latest anchor pair as coloured macroblock dots (DrawPlanes), both from
// core/viz, the CLI's drawing.
//
// Cheap by construction:
//  - the runner keeps a frame only while someone asked for an overlay in the
//    last `kWantedFor` (Wanted()); otherwise it costs one atomic load per
//    anchor;
//  - kept is the newest anchor only (its luma moved, not copied, and its
//    vectors), replaced at each anchor; when the session's run ends it is
//    dropped unless a page was watching then (the last pictures stay);
//  - pictures are drawn on the HTTP thread, on request, at most once per
//    anchor and kind (the PNG is cached until the next anchor), scaled down
//    to at most `max_width_px`.
//
// Thread-safety: the runner's calls and the HTTP side's may run concurrently.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/mv/frame_record.h"
#include "core/planes/plane_extraction.h"

namespace slapse::server {

enum class OverlayKind { kMotionVectors, kPlanes };
// "mv" / "planes" -> the kind; INVALID_ARGUMENT otherwise.
StatusOr<OverlayKind> ParseOverlayKind(const std::string& text);

struct OverlayPng {
  std::string png;           // the encoded picture
  int64_t frame_index = -1;  // the anchor it shows (session timeline)
  int count = 0;             // what it draws: vectors (mv) or planes (planes)
  int width_px = 0, height_px = 0;
};

class FrameOverlays {
 public:
  // How long a request keeps the runner keeping frames.
  static constexpr std::chrono::seconds kWantedFor{30};

  // Runner side. Whether to keep frames at all (someone asked recently).
  bool Wanted() const;
  // The newest anchor frame (luma at `width_px` x `height_px`, or empty: grey).
  void SetAnchor(FrameRecord frame, int width_px, int height_px);
  // The planes of the step whose later anchor is `later_index`.
  void SetPlanes(int64_t earlier_index, int64_t later_index,
                 const std::vector<ExtractedPlane>& planes);
  // Drops what is kept (e.g. nobody asked for a while).
  void Clear();

  // HTTP side: marks the overlays wanted and returns the picture of `kind`
  // for the newest anchor kept, at most `max_width_px` wide. UNAVAILABLE when
  // nothing is kept yet (the next anchor will be).
  StatusOr<OverlayPng> Png(OverlayKind kind, int max_width_px);

 private:
  struct Cached {
    int64_t frame_index = -1;
    int max_width_px = 0;
    OverlayPng png;
  };

  using Luma = std::shared_ptr<const std::vector<uint8_t>>;

  std::atomic<int64_t> wanted_until_ns_{0};
  mutable std::mutex mu_;  // guards everything below
  int width_px_ = 0, height_px_ = 0;
  // The newest anchor with vectors (an I frame has none: the P before it
  // stays), its luma apart (shared with the planes' picture); index -1: none.
  FrameRecord mv_frame_;
  Luma mv_luma_;
  // The newest anchor's luma, and the latest step's planes over it.
  int64_t latest_index_ = -1;
  Luma latest_luma_;
  int64_t planes_earlier_ = -1, planes_later_ = -1;
  std::vector<ExtractedPlane> planes_;
  Luma planes_luma_;
  Cached mv_cache_, planes_cache_;
};

}  // namespace slapse::server
