// Session names and the replica that owns them, for a cluster of servers
// behind a routing proxy (docs/DEPLOY.md, "Scale-out").
//
// (Header only: the client library uses it without linking slapse_api.)
//
// A server started with a replica id (`serve --replica-id slapse-0`) names
// its sessions "sessions/<replica>-<random>", e.g.
// "sessions/slapse-0-x4k...q" (the random part: 26 base32 characters, 128
// bits, never reused); one without a replica id names them
// "sessions/<random>". The random part has no '-', so the owner is
// everything between "sessions/" and the last '-'.
//
// Every per-session rpc of the C++ client (client/lib) carries the owner in
// the metadata header kReplicaHeader; the proxy routes by that header
// (HAProxy cannot read protobuf bodies). Other clients set it themselves:
//   grpcurl -H 'x-slapse-replica: slapse-0' -d '{"name":"sessions/slapse-0-..."}' ...
#pragma once

#include <string>

#include "core/common/status.h"

namespace slapse::api {

// gRPC metadata key (lower case, as HTTP/2 wants) naming the owner replica.
inline constexpr const char* kReplicaHeader = "x-slapse-replica";
// Set by a server on the ListSessions calls it fans out to its peers: the
// peer answers with its own sessions only (no second fan-out).
inline constexpr const char* kFanoutHeader = "x-slapse-fanout";
inline constexpr const char* kFanoutLocal = "local";
inline constexpr const char* kSessionNamePrefix = "sessions/";
// Longest replica id: the name stays within 64 characters after the prefix.
inline constexpr size_t kMaxReplicaIdChars = 32;

// OK for a replica id: 1..kMaxReplicaIdChars of [a-z0-9-], beginning and
// ending with a letter or digit (a DNS label, as a Kubernetes pod name is);
// INVALID_ARGUMENT saying what is wrong otherwise.
inline Status CheckReplicaId(const std::string& id) {
  if (id.empty() || id.size() > kMaxReplicaIdChars) {
    return InvalidArgumentError("a replica id has 1 to " + std::to_string(kMaxReplicaIdChars) +
                                " characters, got " + std::to_string(id.size()));
  }
  for (char c : id) {
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-')) {
      return InvalidArgumentError("replica id '" + id +
                                  "' may hold only a-z, 0-9 and '-' (a DNS label)");
    }
  }
  if (id.front() == '-' || id.back() == '-') {
    return InvalidArgumentError("replica id '" + id +
                                "' must begin and end with a letter or digit");
  }
  return Status::Ok();
}

// The owner replica of session `name`; "" when the name carries none (a
// single server's names) or is not a session name.
inline std::string SessionReplica(const std::string& name) {
  const std::string prefix = kSessionNamePrefix;
  if (name.compare(0, prefix.size(), prefix) != 0) return "";
  const size_t dash = name.rfind('-');
  if (dash == std::string::npos || dash <= prefix.size()) return "";
  std::string replica = name.substr(prefix.size(), dash - prefix.size());
  return CheckReplicaId(replica).ok() ? replica : "";
}

// "sessions/<replica>-<random_id>", or "sessions/<random_id>" for replica "".
inline std::string MakeSessionName(const std::string& replica, const std::string& random_id) {
  return std::string(kSessionNamePrefix) + (replica.empty() ? "" : replica + "-") + random_id;
}

}  // namespace slapse::api
