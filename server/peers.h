// PeerFanout: ListSessions across a cluster of replicas (docs/DEPLOY.md,
// "Scale-out"). The replica that receives a ListSessions asks every peer
// for its own sessions (header api::kFanoutHeader = "local", so a peer does
// not fan out again), merges them with its own and answers the query
// (api/list_query.h) over the union, so filter, order_by and pages mean what
// they mean on one server. A peer that cannot be asked (down, deadline,
// refused) is named in ListSessionsResponse.unreachable_peers; its sessions
// are missing from that answer, never silently.
//
// The caller's `authorization` header is forwarded, so each peer applies
// the same tenant filter (the replicas share one tokens file). A peer that
// turns out to be this replica (its answer's kReplicaHeader equals ours: a
// peer list naming every pod, self included) is skipped.
//
// Thread-safety: Collect may be called from any thread.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "slapse/v1/slapse.grpc.pb.h"

namespace slapse::server {

struct PeerOptions {
  // "host:port" of every replica (this one may be among them).
  std::vector<std::string> addresses;
  // This server's replica id (api/session_name.h).
  std::string self_replica;
  // Deadline of the whole fan-out, per peer (pages included), seconds.
  double timeout_s = 3.0;
  // TLS to the peers (when this server serves TLS): the CA bundle that
  // signed their certificates ("" = the system's roots) and, for peers that
  // want mTLS, this server's own certificate and key as the client's.
  bool tls = false;
  std::string tls_ca_file;
  std::string tls_cert_file;
  std::string tls_key_file;

  // INVALID_ARGUMENT for an empty or malformed address, or timeout_s <= 0.
  Status Check() const;
};

// Parses "host:port,host:port" (spaces allowed around commas) into addresses.
std::vector<std::string> SplitPeerList(const std::string& list);

class PeerFanout {
 public:
  explicit PeerFanout(PeerOptions options);

  struct Result {
    std::vector<v1::Session> sessions;     // every peer's matching sessions
    std::vector<std::string> unreachable;  // "<address>: <CODE>: <message>"
  };
  // Every session of every other replica matching request's filter and
  // state_filter (all pages), the peers asked in parallel.
  // `authorization` ("" = none) is sent on as the caller's.
  Result Collect(const v1::ListSessionsRequest& request, const std::string& authorization) const;

 private:
  struct Peer {
    std::string address;
    std::unique_ptr<v1::SlapseService::Stub> stub;
  };
  // One peer's sessions; `is_self` when the peer is this replica.
  Status CollectOne(const Peer& peer, const v1::ListSessionsRequest& request,
                    const std::string& authorization, std::vector<v1::Session>* sessions,
                    bool* is_self) const;

  PeerOptions options_;
  std::vector<Peer> peers_;
};

}  // namespace slapse::server
