// Who may call the server, and over what: TLS credentials, bearer tokens
// mapped to tenants, and the rule for where an unprotected server may listen.
// This is the one home of the server's auth; the service asks it at the top
// of every rpc (SlapseServiceImpl::Authorize).
//
// Tokens file (JSON, read through core/common/json_io.h):
//   {"tokens": [
//     {"token": "a-long-random-string", "tenant": "acme"},
//     {"token_sha256": "<64 hex digits>", "tenant": "globex", "role": "read_only"}
//   ]}
// Each entry gives the token itself or its SHA-256 (hex of the UTF-8 bytes,
// `printf %s TOKEN | sha256sum`), so the file need not hold the secret. Only
// the SHA-256 is kept in memory; a presented token is hashed and compared
// with every entry in constant time (CRYPTO_memcmp, no early exit). Tokens
// are at least 16 characters; tenants are 1 to 64 of [A-Za-z0-9._-]; roles
// are "read_write" (default) and "read_only" (Get / List / Watch /
// GetTrajectory / GetPlaneMap only). The file is re-read when its mtime,
// size or inode changes (checked at most every tokens_reload_interval_ms,
// at the next rpc) and on Reload() (`slapse serve` calls it on SIGHUP); a
// broken new version is refused with a message on stderr and the old tokens
// stay in force.
//
// Thread-safety: Authenticate and Reload may be called from any thread.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_context.h>

#include "core/common/status.h"

namespace slapse::server {

// gRPC's UNAUTHENTICATED (16), as the server's code spells it.
constexpr StatusCode kUnauthenticated = StatusCode::kUnauthenticated;

struct AuthOptions {
  // PEM files of the server's certificate (chain) and private key: both or
  // neither. With them the server speaks TLS only.
  std::string tls_cert_file;
  std::string tls_key_file;
  // PEM CA bundle: with it, clients must present a certificate it signed (mTLS).
  std::string tls_client_ca_file;
  // Bearer tokens (the format above); empty = no tokens: every caller is the
  // single tenant "" and sees every session.
  std::string tokens_file;
  // How often the tokens file is checked for a change, ms; 0 = at every rpc.
  int64_t tokens_reload_interval_ms = 1000;
  // Whether the server may listen on a non-loopback address without both TLS
  // and tokens (`serve --insecure`). Without it such a server is refused.
  bool allow_insecure = false;

  bool tls() const { return !tls_cert_file.empty(); }
  bool tokens() const { return !tokens_file.empty(); }
  // INVALID_ARGUMENT for a key without a certificate (or the reverse), a
  // client CA without TLS, or a negative reload interval.
  Status Check() const;
};

// Whether `address` (a listen address, without the port) is a loopback one:
// 127.0.0.0/8, ::1 or localhost.
bool IsLoopbackAddress(const std::string& address);

// The safe-default rule: FAILED_PRECONDITION for a non-loopback `address`
// unless TLS and tokens are both configured or allow_insecure is set.
Status CheckListenAddress(const std::string& address, const AuthOptions& options);

// TLS server credentials from the PEM files (InvalidArgument naming an
// unreadable file), or insecure ones without TLS.
StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const AuthOptions& options);

// A caller, as its token says.
struct Caller {
  std::string tenant;  // "" on a server without tokens
  bool read_only = false;
};

class Authenticator {
 public:
  // Reads the tokens file if one is given: INVALID_ARGUMENT (naming the file
  // and the entry, never a token) if it is missing or malformed.
  static StatusOr<std::unique_ptr<Authenticator>> Create(const AuthOptions& options);

  bool enabled() const { return !options_.tokens_file.empty(); }

  // The caller of an rpc from its "authorization: Bearer <token>" metadata:
  // UNAUTHENTICATED when missing, malformed or unknown (the message never
  // holds the token). Without tokens: Caller{"", false}.
  StatusOr<Caller> Authenticate(const grpc::ServerContext& context);
  // The same for a token given directly (tests, and Authenticate's core).
  StatusOr<Caller> AuthenticateToken(const std::string& token);

  // PERMISSION_DENIED when a read-only caller asks for `rpc`, which changes state.
  static Status CheckMayWrite(const Caller& caller, const std::string& rpc);

  // Re-reads the tokens file now; on error keeps the old tokens and says why.
  Status Reload();
  // How many tokens are in force.
  size_t token_count() const;

 private:
  explicit Authenticator(AuthOptions options) : options_(std::move(options)) {}

  struct Entry {
    std::array<unsigned char, 32> sha256;
    std::string tenant;
    bool read_only = false;
  };
  // The file's identity, to notice a change: mtime (ns), size, inode.
  struct FileStamp {
    int64_t mtime_ns = -1, size = -1;
    uint64_t inode = 0;
    bool operator==(const FileStamp& o) const {
      return mtime_ns == o.mtime_ns && size == o.size && inode == o.inode;
    }
  };
  static FileStamp StampOf(const std::string& path);
  static StatusOr<std::vector<Entry>> Load(const std::string& path);
  // Reloads when the interval has passed and the file changed. Call with mu_ held.
  void MaybeReloadLocked();
  Status ReloadLocked();

  const AuthOptions options_;
  mutable std::mutex mu_;
  std::vector<Entry> entries_;
  FileStamp stamp_;
  std::chrono::steady_clock::time_point last_check_{};
};

}  // namespace slapse::server
