#include "core/common/intrinsics_io.h"

#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "core/common/json_io.h"

namespace slapse {

namespace {

// The intrinsics in a parsed intrinsics object; `where` names it in messages.
StatusOr<Intrinsics> IntrinsicsFromJson(const Json& doc, const std::string& where) {
  Intrinsics k;
  for (const auto& [key, value] : {std::pair<const char*, double*>{"fx_px", &k.fx_px},
                                   {"fy_px", &k.fy_px},
                                   {"cx_px", &k.cx_px},
                                   {"cy_px", &k.cy_px}}) {
    if (Status s = GetNumber(doc, key, where, value); !s.ok()) {
      return InvalidArgumentError(s.message());
    }
  }
  // Optional: the size the intrinsics are for (0 = any stream).
  for (const auto& [key, value] :
       {std::pair<const char*, int*>{"width_px", &k.width_px}, {"height_px", &k.height_px}}) {
    if (!doc.contains(key)) continue;
    if (Status s = GetInt(doc, key, where, value); !s.ok()) {
      return InvalidArgumentError(s.message());
    }
  }
  SLAPSE_RETURN_IF_ERROR(ValidateIntrinsics(k, where));
  return k;
}

}  // namespace

StatusOr<Intrinsics> ReadIntrinsicsJson(const std::string& path) {
  if (!std::filesystem::exists(path))
    return NotFoundError("cannot read intrinsics file '" + path + "'");
  auto doc = ReadJsonFile(path);
  if (!doc.ok()) return InvalidArgumentError("intrinsics file: " + doc.status().message());
  return IntrinsicsFromJson(*doc, "intrinsics file '" + path + "'");
}

StatusOr<Intrinsics> ParseIntrinsicsJson(const std::string& text, const std::string& where) {
  auto doc = ParseJsonText(text, where);
  if (!doc.ok()) return InvalidArgumentError("intrinsics: " + doc.status().message());
  return IntrinsicsFromJson(*doc, where);
}

StatusOr<Intrinsics> ParseIntrinsicsSpec(const std::string& spec, int width_px, int height_px) {
  Intrinsics k;
  if (spec.size() > 5 && spec.substr(spec.size() - 5) == ".json") {
    auto r = ReadIntrinsicsJson(spec);
    if (!r.ok()) return r.status();
    k = *r;
  } else if (spec.rfind("hfov=", 0) == 0) {
    char* end = nullptr;
    const double deg = std::strtod(spec.c_str() + 5, &end);
    if (*end != '\0' || !(deg > 1 && deg < 179)) {
      return InvalidArgumentError("intrinsics 'hfov=DEG' needs 1 < DEG < 179, got '" + spec + "'");
    }
    k = Intrinsics::FromHorizontalFov(width_px, height_px, deg);
  } else {
    double v[4];
    const char* p = spec.c_str();
    for (int i = 0; i < 4; ++i) {
      char* end = nullptr;
      v[i] = std::strtod(p, &end);
      if (end == p || (i < 3 && *end != ',') || (i == 3 && *end != '\0')) {
        return InvalidArgumentError(
            "intrinsics must be FILE.json, 'fx,fy,cx,cy' or 'hfov=DEG', got '" + spec + "'");
      }
      p = end + 1;
    }
    k.fx_px = v[0], k.fy_px = v[1], k.cx_px = v[2], k.cy_px = v[3];
    SLAPSE_RETURN_IF_ERROR(ValidateIntrinsics(k, "intrinsics '" + spec + "'"));
  }
  if (k.width_px != 0 && (k.width_px != width_px || k.height_px != height_px)) {
    return InvalidArgumentError("intrinsics are for " + std::to_string(k.width_px) + "x" +
                                std::to_string(k.height_px) + " but the stream is " +
                                std::to_string(width_px) + "x" + std::to_string(height_px));
  }
  k.width_px = width_px;
  k.height_px = height_px;
  return k;
}

}  // namespace slapse
