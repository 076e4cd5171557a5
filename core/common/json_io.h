// slapse's JSON files, read and written through nlohmann::json.
//
// Reading: ReadJsonFile parses a whole file; the Get* functions read one
// member and fail with a message naming the file (or object) and the key:
//   "/d/intrinsics.json: key 'fx_px' is missing"
//   "/d/planes.json: planes[3]: key 'normal_world' is not a list of 3 numbers"
//
// Writing: nlohmann's dump() writes doubles in shortest round-trip form and
// puts every array element on its own line; slapse's files keep their
// historic layout and number formats, so they are written by DumpJson:
//   {
//     "key": value,                      one top-level member a line
//     "list": [
//       {"k": 1, "v": [0.5, 2.0]},       a top-level array: one element a line
//       ...
//     ]
//   }
// with every floating-point number printed by a NumberFormat (by the key of
// the member it is in) and integers, strings (escaped by nlohmann), booleans
// as JSON has them.
#pragma once

#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "core/common/status.h"

namespace slapse {

// Members keep their insertion order, as the files have always had them.
using Json = nlohmann::ordered_json;

// Text of a floating-point value `v` inside the member named `key`, at
// position `index` of the innermost array holding it (0 outside arrays).
using NumberFormat = std::function<std::string(const std::string& key, size_t index, double v)>;

// printf-formats `v` (e.g. FormatDouble("%.6f", v)).
std::string FormatDouble(const char* printf_format, double v);

// "%.17g" for every key: doubles round-trip exactly.
std::string ExactNumber(const std::string& key, size_t index, double v);

// `doc` (an object) in the layout above, ending in a newline.
std::string DumpJson(const Json& doc, const NumberFormat& format);

// `doc` on one line without spaces ({"k":1,"v":[0.5,2]}), no newline: JSON lines.
std::string DumpJsonLine(const Json& doc, const NumberFormat& format);

// Parses `path`: NOT_FOUND if it does not exist, DATA_LOSS (naming the file,
// with nlohmann's reason) if it is not JSON or not an object.
StatusOr<Json> ReadJsonFile(const std::string& path);

// Parses `text` (a whole document held in memory): DATA_LOSS naming `where`
// (e.g. the file) with nlohmann's reason if it is not JSON or not an object.
StatusOr<Json> ParseJsonText(const std::string& text, const std::string& where);

// Member `key` of object `obj`; `where` names the object in messages
// ("/d/planes.json: planes[3]"). DATA_LOSS if missing or of the wrong type.
Status GetNumber(const Json& obj, const std::string& key, const std::string& where, double* out);
Status GetInt(const Json& obj, const std::string& key, const std::string& where, int* out);
Status GetString(const Json& obj, const std::string& key, const std::string& where,
                 std::string* out);
// A list of exactly `n` numbers.
Status GetNumbers(const Json& obj, const std::string& key, const std::string& where, size_t n,
                  double* out);

}  // namespace slapse
