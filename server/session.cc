#include "server/session.h"

#include <google/protobuf/util/time_util.h>

#include <chrono>

#include "server/log.h"

namespace slapse::server {

using google::protobuf::util::TimeUtil;

bool IsTerminal(v1::Session::State s) {
  return s == v1::Session::FINISHED || s == v1::Session::FAILED || s == v1::Session::STOPPED;
}

Session::Session(std::string n, size_t ring, UploadQueueOptions q)
    : name(std::move(n)),
      events(std::make_shared<EventLog>(ring)),
      upload(std::make_shared<UploadQueue>(q)) {}

bool Session::TransitionLocked(v1::Session::State state, const Status& why,
                               const std::string& message) {
  if (IsTerminal(proto.state()) || proto.state() == state) return false;
  proto.set_state(state);
  *proto.mutable_update_time() = TimeUtil::GetCurrentTime();
  if (!why.ok()) {
    proto.mutable_error()->set_code(static_cast<int>(why.code()));
    proto.mutable_error()->set_message(why.message());
  }
  std::string text = why.ok() ? message : why.message();
  if (state == v1::Session::FINISHED && trajectory.empty()) {
    text += (text.empty() ? "" : "; ") + std::string("no poses: ") + no_pose_reason;
  }
  proto.set_state_message(text);
  v1::SessionEvent e;
  e.mutable_state_change()->set_state(state);
  e.mutable_state_change()->set_message(text);
  e.mutable_state_change()->set_error_code(static_cast<int>(why.code()));
  events->Append(std::move(e));
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
