#include "server/auth.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <sys/stat.h>

#include <cctype>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "core/common/json_io.h"

namespace slapse::server {
namespace {

constexpr size_t kMinTokenChars = 16;

Status UnauthenticatedError(std::string message) {
  return Status(kUnauthenticated, std::move(message));
}
constexpr size_t kMaxTenantChars = 64;

std::array<unsigned char, 32> Sha256(const std::string& bytes) {
  std::array<unsigned char, 32> out{};
  unsigned int n = 0;
  EVP_Digest(bytes.data(), bytes.size(), out.data(), &n, EVP_sha256(), nullptr);
  return out;
}

// 64 hex digits -> 32 bytes; false if it is not that.
bool ParseSha256Hex(const std::string& hex, std::array<unsigned char, 32>* out) {
  if (hex.size() != 64) return false;
  for (size_t i = 0; i < 32; ++i) {
    unsigned int byte = 0;
    for (size_t k = 0; k < 2; ++k) {
      const char c = static_cast<char>(std::tolower(static_cast<unsigned char>(hex[2 * i + k])));
      if (!std::isxdigit(static_cast<unsigned char>(c))) return false;
      byte = byte * 16 + (std::isdigit(static_cast<unsigned char>(c)) ? c - '0' : c - 'a' + 10);
    }
    (*out)[i] = static_cast<unsigned char>(byte);
  }
  return true;
}

bool ValidTenant(const std::string& t) {
  if (t.empty() || t.size() > kMaxTenantChars) return false;
  for (char c : t) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '_' && c != '-') {
      return false;
    }
  }
  return true;
}

StatusOr<std::string> ReadPem(const std::string& path, const std::string& flag) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return InvalidArgumentError(flag + " '" + path + "' cannot be read");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (ss.str().find("-----BEGIN ") == std::string::npos) {
    return InvalidArgumentError(flag + " '" + path + "' is not a PEM file (no -----BEGIN line)");
  }
  return ss.str();
}

}  // namespace

Status AuthOptions::Check() const {
  if (tls_cert_file.empty() != tls_key_file.empty()) {
    return InvalidArgumentError("TLS needs both a certificate and its key (--tls-cert, --tls-key)");
  }
  if (!tls_client_ca_file.empty() && !tls()) {
    return InvalidArgumentError(
        "--tls-client-ca (mTLS) needs TLS: give --tls-cert and --tls-key too");
  }
  if (tokens_reload_interval_ms < 0) {
    return InvalidArgumentError("tokens_reload_interval_ms must be >= 0");
  }
  return Status::Ok();
}

bool IsLoopbackAddress(const std::string& address) {
  std::string a = address;
  if (a.size() >= 2 && a.front() == '[' && a.back() == ']') a = a.substr(1, a.size() - 2);
  return a == "localhost" || a == "::1" || a.rfind("127.", 0) == 0;
}

Status CheckListenAddress(const std::string& address, const AuthOptions& options) {
  if (IsLoopbackAddress(address) || options.allow_insecure) return Status::Ok();
  if (options.tls() && options.tokens()) return Status::Ok();
  return FailedPreconditionError(
      "refusing to listen on " + address + " without " +
      (options.tls()      ? "bearer tokens"
       : options.tokens() ? "TLS"
                          : "TLS and bearer tokens") +
      ": anyone who reaches the port could read, stop and delete every session. Give "
      "--tls-cert/--tls-key and --tokens-file, listen on 127.0.0.1, or pass --insecure to "
      "accept the risk (e.g. behind an authenticating proxy)");
}

StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const AuthOptions& options) {
  SLAPSE_RETURN_IF_ERROR(options.Check());
  if (!options.tls()) return grpc::InsecureServerCredentials();
  auto cert = ReadPem(options.tls_cert_file, "--tls-cert");
  if (!cert.ok()) return cert.status();
  auto key = ReadPem(options.tls_key_file, "--tls-key");
  if (!key.ok()) return key.status();
  grpc::SslServerCredentialsOptions ssl(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  ssl.pem_key_cert_pairs.push_back({*key, *cert});
  if (!options.tls_client_ca_file.empty()) {
    auto ca = ReadPem(options.tls_client_ca_file, "--tls-client-ca");
    if (!ca.ok()) return ca.status();
    ssl.pem_root_certs = *ca;
    ssl.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(ssl);
}

StatusOr<std::unique_ptr<Authenticator>> Authenticator::Create(const AuthOptions& options) {
  SLAPSE_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<Authenticator> auth(new Authenticator(options));
  if (auth->enabled()) {
    std::lock_guard<std::mutex> lock(auth->mu_);
    SLAPSE_RETURN_IF_ERROR(auth->ReloadLocked());
    auth->last_check_ = std::chrono::steady_clock::now();
  }
  return auth;
}

StatusOr<std::vector<Authenticator::Entry>> Authenticator::Load(const std::string& path) {
  auto doc = ReadJsonFile(path);
  if (!doc.ok()) {
    return InvalidArgumentError("tokens file: " + doc.status().message() +
                                " (want {\"tokens\": [{\"token\": ..., \"tenant\": ...}]})");
  }
  const std::string where = "tokens file " + path;
  if (!doc->contains("tokens") || !(*doc)["tokens"].is_array()) {
    return InvalidArgumentError(where + ": key 'tokens' (a list) is missing");
  }
  std::vector<Entry> entries;
  const Json& list = (*doc)["tokens"];
  for (size_t i = 0; i < list.size(); ++i) {
    const Json& e = list[i];
    const std::string at = where + ": tokens[" + std::to_string(i) + "]";
    if (!e.is_object()) return InvalidArgumentError(at + " is not an object");
    Entry entry;
    const bool has_token = e.contains("token"), has_hash = e.contains("token_sha256");
    if (has_token == has_hash) {
      return InvalidArgumentError(at + ": give exactly one of 'token' and 'token_sha256'");
    }
    if (has_token) {
      if (!e["token"].is_string() || e["token"].get<std::string>().size() < kMinTokenChars) {
        return InvalidArgumentError(at + ": 'token' must be a string of at least " +
                                    std::to_string(kMinTokenChars) + " characters");
      }
      entry.sha256 = Sha256(e["token"].get<std::string>());
    } else if (!e["token_sha256"].is_string() ||
               !ParseSha256Hex(e["token_sha256"].get<std::string>(), &entry.sha256)) {
      return InvalidArgumentError(at + ": 'token_sha256' must be 64 hex digits");
    }
    if (!e.contains("tenant") || !e["tenant"].is_string() ||
        !ValidTenant(e["tenant"].get<std::string>())) {
      return InvalidArgumentError(at + ": 'tenant' must be 1 to 64 of [A-Za-z0-9._-]");
    }
    entry.tenant = e["tenant"].get<std::string>();
    const std::string role = e.contains("role") && e["role"].is_string()
                                 ? e["role"].get<std::string>()
                                 : (e.contains("role") ? "?" : "read_write");
    if (role != "read_write" && role != "read_only") {
      return InvalidArgumentError(at + ": 'role' must be \"read_write\" or \"read_only\"");
    }
    entry.read_only = role == "read_only";
    for (size_t k = 0; k < entries.size(); ++k) {
      if (entries[k].sha256 == entry.sha256) {
        return InvalidArgumentError(at + ": the same token as tokens[" + std::to_string(k) + "]");
      }
    }
    entries.push_back(std::move(entry));
  }
  return entries;
}

Authenticator::FileStamp Authenticator::StampOf(const std::string& path) {
  struct stat st {};
  FileStamp stamp;
  if (stat(path.c_str(), &st) == 0) {
    stamp = {int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec,
             static_cast<int64_t>(st.st_size), static_cast<uint64_t>(st.st_ino)};
  }
  return stamp;
}

Status Authenticator::ReloadLocked() {
  const FileStamp stamp = StampOf(options_.tokens_file);
  auto entries = Load(options_.tokens_file);
  stamp_ = stamp;  // a broken version is not retried until it changes again
  if (!entries.ok()) return entries.status();
  entries_ = std::move(*entries);
  return Status::Ok();
}

Status Authenticator::Reload() {
  if (!enabled()) return Status::Ok();
  std::lock_guard<std::mutex> lock(mu_);
  Status s = ReloadLocked();
  if (!s.ok()) {
    std::fprintf(stderr, "slapse: tokens not reloaded (the old ones stay in force): %s\n",
                 s.message().c_str());
  }
  return s;
}

void Authenticator::MaybeReloadLocked() {
  const auto now = std::chrono::steady_clock::now();
  if (now - last_check_ < std::chrono::milliseconds(options_.tokens_reload_interval_ms)) return;
  last_check_ = now;
  const FileStamp stamp = StampOf(options_.tokens_file);
  if (stamp == stamp_) return;
  Status s = ReloadLocked();
  if (!s.ok()) {
    std::fprintf(stderr, "slapse: tokens not reloaded (the old ones stay in force): %s\n",
                 s.message().c_str());
  }
}

size_t Authenticator::token_count() const {
  std::lock_guard<std::mutex> lock(mu_);
  return entries_.size();
}

StatusOr<Caller> Authenticator::AuthenticateToken(const std::string& token) {
  if (!enabled()) return Caller{};
  const std::array<unsigned char, 32> digest = Sha256(token);
  std::lock_guard<std::mutex> lock(mu_);
  MaybeReloadLocked();
  // Every entry is compared (no early exit), each in constant time.
  const Entry* match = nullptr;
  for (const Entry& e : entries_) {
    if (CRYPTO_memcmp(e.sha256.data(), digest.data(), digest.size()) == 0) match = &e;
  }
  if (match == nullptr) {
    return UnauthenticatedError("the bearer token is not valid (unknown or revoked)");
  }
  return Caller{match->tenant, match->read_only};
}

StatusOr<Caller> Authenticator::Authenticate(const grpc::ServerContext& context) {
  if (!enabled()) return Caller{};
  const auto& md = context.client_metadata();
  const auto it = md.find("authorization");
  if (it == md.end()) {
    return UnauthenticatedError(
        "this server requires a bearer token: send the metadata 'authorization: Bearer "
        "<token>' (slapse CLI: --token or the SLAPSE_TOKEN environment variable)");
  }
  const std::string value(it->second.data(), it->second.size());
  const std::string scheme = "bearer ";
  bool bearer = value.size() > scheme.size();
  for (size_t i = 0; bearer && i < scheme.size(); ++i) {
    bearer = std::tolower(static_cast<unsigned char>(value[i])) == scheme[i];
  }
  if (!bearer) {
    return UnauthenticatedError("the authorization metadata is not 'Bearer <token>'");
  }
  return AuthenticateToken(value.substr(scheme.size()));
}

Status Authenticator::CheckMayWrite(const Caller& caller, const std::string& rpc) {
  if (!caller.read_only) return Status::Ok();
  return Status(StatusCode::kPermissionDenied,
                "tenant '" + caller.tenant + "' has a read-only token: " + rpc +
                    " is not allowed (read-only tokens may Get, List, Watch and read "
                    "trajectories and plane maps)");
}

}  // namespace slapse::server
