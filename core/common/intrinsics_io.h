// Reading camera intrinsics from what a user types or a file holds.
#pragma once

#include <string>

#include "core/common/camera.h"
#include "core/common/status.h"

namespace slapse {

// Reads an intrinsics JSON object with the keys fx_px, fy_px, cx_px, cy_px and
// optionally width_px, height_px (the simulator's intrinsics.json).
StatusOr<Intrinsics> ReadIntrinsicsJson(const std::string& path);

// The same from the text of such a file held in memory; `where` names it in
// messages (e.g. "intrinsics file 'k.json'").
StatusOr<Intrinsics> ParseIntrinsicsJson(const std::string& text, const std::string& where);

// Parses a command-line intrinsics spec for a width x height stream:
//   "FILE.json"         as ReadIntrinsicsJson
//   "fx,fy,cx,cy"       pixels, principal point in the pixel-centre convention
//   "hfov=DEG"          a centred pinhole with that horizontal field of view
StatusOr<Intrinsics> ParseIntrinsicsSpec(const std::string& spec, int width_px, int height_px);

}  // namespace slapse
