#include "core/common/json_io.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace slapse {
namespace {

// `j` on one line; `key` names the member it is in, `index` its place in an array.
// `comma` and `colon` separate elements and keys from values.
void DumpInline(const Json& j, const std::string& key, size_t index, const NumberFormat& format,
                const char* comma, const char* colon, std::string* out) {
  switch (j.type()) {
    case Json::value_t::object: {
      *out += "{";
      bool first = true;
      for (const auto& [k, v] : j.items()) {
        *out += first ? "" : comma;
        first = false;
        *out += Json(k).dump() + colon;
        DumpInline(v, k, 0, format, comma, colon, out);
      }
      *out += "}";
      return;
    }
    case Json::value_t::array: {
      *out += "[";
      for (size_t i = 0; i < j.size(); ++i) {
        *out += i ? comma : "";
        DumpInline(j[i], key, i, format, comma, colon, out);
      }
      *out += "]";
      return;
    }
    case Json::value_t::number_float:
      *out += format(key, index, j.get<double>());
      return;
    default:  // strings (escaped), integers, booleans, null: as nlohmann writes them
      *out += j.dump();
      return;
  }
}

}  // namespace

std::string FormatDouble(const char* printf_format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), printf_format, v);
  return buf;
}

std::string ExactNumber(const std::string& /*key*/, size_t /*index*/, double v) {
  return FormatDouble("%.17g", v);
}

std::string DumpJson(const Json& doc, const NumberFormat& format) {
  std::string out = "{";
  bool first = true;
  for (const auto& [key, value] : doc.items()) {
    out += first ? "\n  " : ",\n  ";
    first = false;
    out += Json(key).dump() + ": ";
    if (!value.is_array()) {
      DumpInline(value, key, 0, format, ", ", ": ", &out);
      continue;
    }
    out += "[";
    for (size_t i = 0; i < value.size(); ++i) {
      out += i ? ",\n    " : "\n    ";
      DumpInline(value[i], key, i, format, ", ", ": ", &out);
    }
    out += "\n  ]";
  }
  out += "\n}\n";
  return out;
}

std::string DumpJsonLine(const Json& doc, const NumberFormat& format) {
  std::string out;
  DumpInline(doc, "", 0, format, ",", ":", &out);
  return out;
}

StatusOr<Json> ReadJsonFile(const std::string& path) {
  if (!std::filesystem::exists(path)) return NotFoundError("missing " + path);
  std::ifstream in(path);
  if (!in) return NotFoundError("cannot read " + path);
  std::stringstream text;
  text << in.rdbuf();
  return ParseJsonText(text.str(), path);
}

StatusOr<Json> ParseJsonText(const std::string& text, const std::string& where) {
  Json doc;
  try {
    doc = Json::parse(text);
  } catch (const Json::exception& e) {
    // parse_error, and out_of_range for a number beyond a double ("1e999").
    return DataLossError(where + ": not valid JSON: " + e.what());
  }
  if (!doc.is_object()) return DataLossError(where + ": not a JSON object");
  return doc;
}

namespace {

// The member, or the error that it is missing.
StatusOr<const Json*> Member(const Json& obj, const std::string& key, const std::string& where) {
  if (!obj.is_object()) return DataLossError(where + ": not a JSON object");
  const auto it = obj.find(key);
  if (it == obj.end()) return DataLossError(where + ": key '" + key + "' is missing");
  return &*it;
}

}  // namespace

Status GetNumber(const Json& obj, const std::string& key, const std::string& where, double* out) {
  auto m = Member(obj, key, where);
  if (!m.ok()) return m.status();
  if (!(*m)->is_number()) return DataLossError(where + ": key '" + key + "' is not a number");
  *out = (*m)->get<double>();
  return Status::Ok();
}

Status GetInt(const Json& obj, const std::string& key, const std::string& where, int* out) {
  double v = 0;
  SLAPSE_RETURN_IF_ERROR(GetNumber(obj, key, where, &v));
  if (!(v >= -2147483648.0 && v <= 2147483647.0) || v != std::floor(v)) {
    return DataLossError(where + ": key '" + key + "' is not an integer");
  }
  *out = static_cast<int>(v);
  return Status::Ok();
}

Status GetString(const Json& obj, const std::string& key, const std::string& where,
                 std::string* out) {
  auto m = Member(obj, key, where);
  if (!m.ok()) return m.status();
  if (!(*m)->is_string()) return DataLossError(where + ": key '" + key + "' is not a string");
  *out = (*m)->get<std::string>();
  return Status::Ok();
}

Status GetNumbers(const Json& obj, const std::string& key, const std::string& where, size_t n,
                  double* out) {
  auto m = Member(obj, key, where);
  if (!m.ok()) return m.status();
  const Json& list = **m;
  bool ok = list.is_array() && list.size() == n;
  for (size_t i = 0; ok && i < n; ++i) ok = list[i].is_number();
  if (!ok) {
    return DataLossError(where + ": key '" + key + "' is not a list of " + std::to_string(n) +
                         " numbers");
  }
  for (size_t i = 0; i < n; ++i) out[i] = list[i].get<double>();
  return Status::Ok();
}

}  // namespace slapse
