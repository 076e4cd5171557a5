#include "server/session.h"

#include <google/protobuf/util/time_util.h>

#include <chrono>
#include <cstdio>

#include "server/log.h"

namespace slapse::server {

using google::protobuf::util::TimeUtil;

bool IsTerminal(v1::Session::State s) {
  return s == v1::Session::FINISHED || s == v1::Session::FAILED || s == v1::Session::STOPPED ||
         s == v1::Session::EXPIRED;
}

Session::Session(std::string n, size_t ring, UploadQueueOptions q, std::shared_ptr<Store> st,
                 int64_t ord, uint64_t last_sequence, bool closed)
    : name(std::move(n)),
      store(std::move(st)),
      ordinal(ord),
      events(std::make_shared<EventLog>(ring, last_sequence, closed)),
      upload(std::make_shared<UploadQueue>(q)) {
  if (store == nullptr) return;
  Store* db = store.get();
  const int64_t key = ordinal;
  // The log must not keep the store alive by itself past the manager:
  // watchers hold logs, the manager holds the store; both end at shutdown.
  events->SetStore([this](const std::vector<v1::SessionEvent>& e) { CommitStep(StoreStep{}, e); },
                   [db, key](uint64_t after, size_t max, std::vector<v1::SessionEvent>* out) {
                     return db->ReadEvents(key, after, max, out);
                   });
}

void Session::CommitStep(const StoreStep& step, const std::vector<v1::SessionEvent>& e) const {
  if (store == nullptr) return;
  const Status s = store->Commit(ordinal, step, e);
  if (!s.ok()) std::fprintf(stderr, "slapse: %s: %s\n", name.c_str(), s.message().c_str());
}

bool Session::Expire(const std::string& message) {
  std::lock_guard<std::mutex> lock(mu);
  if (!IsTerminal(proto.state()) || proto.state() == v1::Session::EXPIRED) return false;
  proto.set_state(v1::Session::EXPIRED);
  proto.set_state_message(message);
  *proto.mutable_update_time() = TimeUtil::GetCurrentTime();
  v1::SessionEvent e;
  e.mutable_state_change()->set_state(v1::Session::EXPIRED);
  e.mutable_state_change()->set_message(message);
  events->Expire(std::move(e), [this](const std::vector<v1::SessionEvent>& batch) {
    v1::Session row = proto;
    row.set_last_sequence(batch.back().sequence());
    CommitStep(StoreStep{}, batch);  // the expiry event; then the rest goes
    if (store != nullptr) {
      const Status s = store->ExpireResults(ordinal, row, batch.back().sequence());
      if (!s.ok()) std::fprintf(stderr, "slapse: %s: %s\n", name.c_str(), s.message().c_str());
    }
  });
  points = 0;
  return true;
}

bool Session::TransitionLocked(v1::Session::State state, const Status& why,
                               const std::string& message) {
  if (IsTerminal(proto.state()) || proto.state() == state || suspended) return false;
  proto.set_state(state);
  *proto.mutable_update_time() = TimeUtil::GetCurrentTime();
  if (!why.ok()) {
    proto.mutable_error()->set_code(static_cast<int>(why.code()));
    proto.mutable_error()->set_message(why.message());
  }
  std::string text = why.ok() ? message : why.message();
  if (state == v1::Session::FINISHED && points == 0) {
    text += (text.empty() ? "" : "; ") + std::string("no poses: ") + no_pose_reason;
  }
  proto.set_state_message(text);
  v1::SessionEvent e;
  e.mutable_state_change()->set_state(state);
  e.mutable_state_change()->set_message(text);
  e.mutable_state_change()->set_error_code(static_cast<int>(why.code()));
  // The session row with its StateChange, in one transaction (`mu` is held,
  // so the row is this transition's).
  std::vector<v1::SessionEvent> batch;
  batch.push_back(std::move(e));
  events->AppendBatch(std::move(batch), [this](const std::vector<v1::SessionEvent>& b) {
    v1::Session row = proto;
    row.set_last_sequence(b.back().sequence());
    StoreStep step;
    step.session = &row;
    step.metric = metric;
    CommitStep(step, b);
  });
  Log(state == v1::Session::FAILED ? LogLevel::kError : LogLevel::kInfo, name, "state",
      v1::Session::State_Name(state) + (text.empty() ? "" : ": " + text));
  if (IsTerminal(state)) {
    events->Close();
    upload->Close(why.ok()
                      ? FailedPreconditionError("the session is " + v1::Session::State_Name(state))
                      : why);
  }
  return true;
}

bool Session::Transition(v1::Session::State state, const Status& why, const std::string& message) {
  std::lock_guard<std::mutex> lock(mu);
  return TransitionLocked(state, why, message);
}

void Session::Stop(const std::string& why) {
  stop = true;
  // Transition takes `mu`, so a reconnect wait either saw `stop` or is
  // blocked in wait_for and gets the notification.
  Transition(v1::Session::STOPPED, Status::Ok(), why);
  stop_cv.notify_all();
}

void Session::Suspend() {
  {
    std::lock_guard<std::mutex> lock(mu);
    suspended = true;
    stop = true;
  }
  events->Close();
  upload->Close(
      UnavailableError("the server is shutting down; upload the stream again to a new session"));
  stop_cv.notify_all();
}

bool Session::WaitForStop(int ms) {
  std::unique_lock<std::mutex> lock(mu);
  return stop_cv.wait_for(lock, std::chrono::milliseconds(ms), [this] { return stop.load(); });
}

void Session::End(const Ending& ending) {
  std::lock_guard<std::mutex> lock(mu);
  if (stop) {
    TransitionLocked(v1::Session::STOPPED, Status::Ok(), "stopped");
  } else {
    TransitionLocked(ending.state, ending.error, ending.message);
  }
}

void Session::EndStream(Status status, const std::string& finished_message) {
  std::lock_guard<std::mutex> lock(mu);
  if (!ingest_error.ok()) status = ingest_error;
  if (stop) {
    TransitionLocked(v1::Session::STOPPED, Status::Ok(), "stopped");
  } else if (status.code() == StatusCode::kOutOfRange) {
    TransitionLocked(v1::Session::FINISHED, Status::Ok(), finished_message);
  } else {
    TransitionLocked(v1::Session::FAILED, status, "");
  }
}

v1::Session Session::Snapshot() const {
  std::lock_guard<std::mutex> lock(mu);
  v1::Session out = proto;
  out.set_last_sequence(events->last_sequence());
  return out;
}

}  // namespace slapse::server
