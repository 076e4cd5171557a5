// Fuzzes how slapse reads camera intrinsics and its JSON files:
// ParseIntrinsicsSpec (a command-line spec: "fx,fy,cx,cy", "hfov=DEG"),
// ParseIntrinsicsJson (an intrinsics.json's text, as ReadIntrinsicsJson reads
// it) and ParseJsonText + the Get* readers + DumpJson (every JSON file).
//
// The input's first byte picks the target and (for specs) the stream size;
// the rest is the text. Invariants beyond "no crash / leak / UB":
//  - parsed intrinsics pass ValidateIntrinsics; a spec's result has the
//    stream's width/height;
//  - a parsed JSON object written by DumpJson(ExactNumber) and parsed again is
//    equal to itself (numbers round-trip); Get* readers never throw.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "core/common/camera.h"
#include "core/common/intrinsics_io.h"
#include "core/common/json_io.h"

namespace {

void Check(bool ok, const char* what, const std::string& input) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_intrinsics: invariant violated: %s\ninput: '%s'\n", what,
               input.c_str());
  std::abort();
}

void FuzzSpec(uint8_t selector, const std::string& spec) {
  // FILE.json specs read files; the file's text is fuzzed below instead.
  if (spec.size() > 5 && spec.compare(spec.size() - 5, 5, ".json") == 0) return;
  const int width_px = 16 * (1 + selector % 120), height_px = 16 * (1 + selector / 2 % 68);
  auto k = slapse::ParseIntrinsicsSpec(spec, width_px, height_px);
  if (!k.ok()) return;
  Check(slapse::ValidateIntrinsics(*k).ok(), "a parsed spec is not valid intrinsics", spec);
  Check(k->width_px == width_px && k->height_px == height_px, "spec lost the stream size", spec);
}

void FuzzJson(const std::string& text) {
  auto k = slapse::ParseIntrinsicsJson(text, "fuzz.json");
  if (k.ok()) Check(slapse::ValidateIntrinsics(*k).ok(), "parsed JSON intrinsics invalid", text);

  auto doc = slapse::ParseJsonText(text, "fuzz.json");
  if (!doc.ok()) return;
  double v3[3];
  double d;
  int i;
  std::string s;
  for (const auto& [key, value] : doc->items()) {
    (void)slapse::GetNumber(*doc, key, "fuzz.json", &d);
    (void)slapse::GetInt(*doc, key, "fuzz.json", &i);
    (void)slapse::GetString(*doc, key, "fuzz.json", &s);
    (void)slapse::GetNumbers(*doc, key, "fuzz.json", 3, v3);
  }
  const std::string dumped = slapse::DumpJson(*doc, slapse::ExactNumber);
  auto again = slapse::ParseJsonText(dumped, "dumped");
  Check(again.ok(), "DumpJson wrote unparsable JSON", text);
  Check(*again == *doc, "DumpJson + parse changed the document", text);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0 || size > 64 << 10) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] % 2 == 0) {
    FuzzSpec(data[0], text);
  } else {
    FuzzJson(text);
  }
  return 0;
}
