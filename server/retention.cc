// Retention (SessionManagerOptions::retention_ttl_s, retention_max_store_bytes):
// finished sessions expire (Session::Expire: state EXPIRED, a StateChange
// saying why, their results deleted from the store), after a TTL or, while
// the store is over its size budget (Store::SizeBytes), oldest end time
// first. Active sessions are never touched.
#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cstdio>

#include "server/log.h"
#include "server/session_manager.h"

namespace slapse::server {
namespace {

using google::protobuf::util::TimeUtil;

// The budget check's period: cheap (three PRAGMAs), so often enough that a
// burst of results is trimmed within a second.
constexpr int64_t kBudgetPeriodMs = 1000;

bool Expirable(v1::Session::State state) {
  return IsTerminal(state) && state != v1::Session::EXPIRED;
}

// `bytes` in MiB for people: "500 MiB", "0.25 MiB".
std::string Mib(int64_t bytes) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.3g MiB", static_cast<double>(bytes) / (1 << 20));
  return text;
}

}  // namespace

void SessionManager::RetentionLoop() {
  const int64_t ttl_s = options_.retention_ttl_s;
  int64_t period_ms = ttl_s > 0 ? std::clamp<int64_t>(ttl_s * 250, 200, 60000) : kBudgetPeriodMs;
  if (options_.retention_max_store_bytes > 0) period_ms = std::min(period_ms, kBudgetPeriodMs);
  std::unique_lock<std::mutex> lock(mu_);
  while (!shutting_down_) {
    retention_cv_.wait_for(lock, std::chrono::milliseconds(period_ms),
                           [this] { return shutting_down_; });
    if (shutting_down_) break;
    std::vector<std::shared_ptr<Session>> all;
    for (const auto& [ordinal, s] : sessions_) all.push_back(s);
    lock.unlock();
    int expired = ttl_s > 0 ? ExpireByTtl(all) : 0;
    if (options_.retention_max_store_bytes > 0) expired += ExpireOverBudget(all);
    if (expired > 0) {
      const Status reclaimed = store_->Reclaim();
      Log(reclaimed.ok() ? LogLevel::kInfo : LogLevel::kWarning, "", "retention",
          "expired " + std::to_string(expired) + " finished session(s); the store holds " +
              Mib(store_->SizeBytes()) + " of data" +
              (reclaimed.ok() ? ""
                              : "; giving back its free pages failed: " + reclaimed.message()));
    }
    lock.lock();
  }
}

int SessionManager::ExpireByTtl(const std::vector<std::shared_ptr<Session>>& all) {
  const int64_t ttl_s = options_.retention_ttl_s;
  const auto now = TimeUtil::GetCurrentTime();
  int expired = 0;
  for (const auto& s : all) {
    v1::Session snap = s->Snapshot();
    if (!Expirable(snap.state())) continue;
    if (TimeUtil::DurationToSeconds(now - snap.update_time()) < ttl_s) continue;
    expired += s->Expire("its results were deleted by the retention policy: it ended (" +
                         v1::Session::State_Name(snap.state()) + ") more than " +
                         std::to_string(ttl_s) + " s ago (serve --retention-ttl-s)");
  }
  return expired;
}

int SessionManager::ExpireOverBudget(const std::vector<std::shared_ptr<Session>>& all) {
  const int64_t budget = options_.retention_max_store_bytes;
  int64_t size = store_->SizeBytes();
  if (size <= budget) {
    over_budget_logged_ = false;
    return 0;
  }
  // The finished sessions, oldest end (their last update: the terminal state) first.
  std::vector<std::pair<v1::Session, std::shared_ptr<Session>>> finished;
  for (const auto& s : all) {
    v1::Session snap = s->Snapshot();
    if (Expirable(snap.state())) finished.emplace_back(std::move(snap), s);
  }
  std::stable_sort(finished.begin(), finished.end(), [](const auto& a, const auto& b) {
    return a.first.update_time() < b.first.update_time();
  });
  int expired = 0;
  for (const auto& [snap, s] : finished) {
    if (size <= budget) break;
    const bool done = s->Expire(
        "its results were deleted by the retention policy: the store (" + Mib(size) +
        ") was over its " + Mib(budget) + " budget and it was the oldest finished session (" +
        v1::Session::State_Name(snap.state()) + ") (serve --retention-max-store-mb)");
    expired += done;
    size = store_->SizeBytes();
  }
  if (size > budget && !over_budget_logged_) {
    Log(LogLevel::kWarning, "", "retention",
        "the store (" + Mib(size) + ") is over its " + Mib(budget) +
            " budget with no finished session left to expire: the rest is active sessions' "
            "data (and expired sessions' rows), which retention does not delete; raise "
            "serve --retention-max-store-mb or stop or delete sessions");
    over_budget_logged_ = true;
  } else if (size <= budget) {
    over_budget_logged_ = false;
  }
  return expired;
}

}  // namespace slapse::server
