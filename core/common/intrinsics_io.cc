#include "core/common/intrinsics_io.h"

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace slapse {
namespace {

// The number after "key": in a flat JSON text, or NaN.
double JsonNumber(const std::string& text, const std::string& key) {
  const size_t k = text.find("\"" + key + "\"");
  if (k == std::string::npos) return NAN;
  const size_t colon = text.find(':', k);
  if (colon == std::string::npos) return NAN;
  const char* begin = text.c_str() + colon + 1;
  char* end = nullptr;
  const double v = std::strtod(begin, &end);
  return end == begin ? NAN : v;
}

Status Validate(const Intrinsics& k, const std::string& what) {
  if (!(k.fx_px > 0 && k.fy_px > 0 && std::isfinite(k.cx_px) && std::isfinite(k.cy_px))) {
    return InvalidArgumentError(what +
                                ": focal lengths must be positive and the principal "
                                "point finite");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<Intrinsics> ReadIntrinsicsJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) return NotFoundError("cannot read intrinsics file '" + path + "'");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  Intrinsics k;
  k.fx_px = JsonNumber(text, "fx_px");
  k.fy_px = JsonNumber(text, "fy_px");
  k.cx_px = JsonNumber(text, "cx_px");
  k.cy_px = JsonNumber(text, "cy_px");
  const double w = JsonNumber(text, "width_px"), h = JsonNumber(text, "height_px");
  k.width_px = std::isfinite(w) ? static_cast<int>(w) : 0;
  k.height_px = std::isfinite(h) ? static_cast<int>(h) : 0;
  SLAPSE_RETURN_IF_ERROR(
      Validate(k, "intrinsics file '" + path + "' (keys fx_px fy_px cx_px cy_px)"));
  return k;
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
    SLAPSE_RETURN_IF_ERROR(Validate(k, "intrinsics '" + spec + "'"));
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
