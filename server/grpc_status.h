// The one place where slapse::Status becomes grpc::Status (codes are equal by
// construction, see core/common/status.h).
#pragma once

#include <grpcpp/support/status.h>

#include "core/common/status.h"

namespace slapse::server {

inline grpc::Status ToGrpcStatus(const Status& s) {
  if (s.ok()) return grpc::Status::OK;
  return grpc::Status(static_cast<grpc::StatusCode>(s.code()), s.message());
}

}  // namespace slapse::server
