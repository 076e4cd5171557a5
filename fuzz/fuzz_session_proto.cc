// Fuzzes what a CreateSession request carries: the input is parsed as a
// serialized v1::Session (as gRPC hands it to the service), then checked by
// api::ValidateSession; an accepted one is converted by
// api::PipelineOptionsFromProto and api::IntrinsicsFromProto.
//
// Invariants beyond "no crash / leak / UB":
//  - a refused request has INVALID_ARGUMENT and a non-empty message;
//  - an accepted request's intrinsics pass ValidateIntrinsics, and its
//    pipeline options convert without crashing;
//  - validation is deterministic (a re-serialized, re-parsed request gets the
//    same verdict).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <google/protobuf/stubs/logging.h>

#include "api/convert.h"
#include "api/validate.h"
#include "core/common/camera.h"
#include "slapse/v1/slapse.pb.h"

namespace {

void Check(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_session_proto: invariant violated: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Parsing refuses strings with invalid UTF-8 and logs each one: quiet.
  google::protobuf::SetLogHandler(nullptr);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  slapse::v1::Session request;
  if (!request.ParseFromArray(data, static_cast<int>(size))) return 0;
  const slapse::Status s = slapse::api::ValidateSession(request);
  slapse::v1::Session again;
  Check(again.ParseFromString(request.SerializeAsString()), "re-serialized request unparsable");
  Check(slapse::api::ValidateSession(again).code() == s.code(), "verdict not deterministic");
  if (!s.ok()) {
    Check(s.code() == slapse::StatusCode::kInvalidArgument, "refusal is not INVALID_ARGUMENT");
    Check(!s.message().empty(), "refusal without a message");
    return 0;
  }
  const slapse::Intrinsics k = slapse::api::IntrinsicsFromProto(request.intrinsics());
  Check(slapse::ValidateIntrinsics(k).ok(), "accepted intrinsics are invalid");
  (void)slapse::api::PipelineOptionsFromProto(request.pipeline_options());
  return 0;
}
