#include "server/session_runner.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <mutex>
#include <string>
#include <vector>

#include "api/convert.h"
#include "api/validate.h"

namespace slapse::server {
namespace {

using google::protobuf::util::TimeUtil;

// The wall clock to the nanosecond (TimeUtil::GetCurrentTime of protobuf 3.21
// has whole seconds only).
google::protobuf::Timestamp PreciseNow() {
  return TimeUtil::NanosecondsToTimestamp(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                              std::chrono::system_clock::now().time_since_epoch())
                                              .count());
}

int64_t SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

v1::PlaneEvent::Kind KindToProto(PlaneChange::Kind kind) {
  switch (kind) {
    case PlaneChange::Kind::kAdded:
      return v1::PlaneEvent::ADDED;
    case PlaneChange::Kind::kRemoved:
      return v1::PlaneEvent::REMOVED;
    case PlaneChange::Kind::kUpdated:
      break;
  }
  return v1::PlaneEvent::UPDATED;
}

}  // namespace

SessionRunner::SessionRunner(std::shared_ptr<Session> session) : session_(std::move(session)) {
  source_ = IngestSource::Make(session_->Snapshot(), session_->upload);
}

bool SessionRunner::Interrupt() {
  if (session_->stop.load()) return true;
  if (source_->network() && SteadyNowNs() > deadline_ns_.load()) {
    timed_out_ = true;
    return true;
  }
  return false;
}

void SessionRunner::SetDeadline(int ms) { deadline_ns_ = SteadyNowNs() + int64_t{ms} * 1000000; }

void SessionRunner::EndStream(const Status& status) {
  session_->EndStream(status, source_->EndOfStreamMessage());
}

// One pass per connection: upload, RTSP push and RTP/SDP have one; RTSP pull
// connects again after an outage while its policy allows.
void SessionRunner::Run() {
  if (session_->stop) return EndStream(CancelledError("stopped"));
  for (;;) {
    SetDeadline(source_->start_timeout_ms());
    timed_out_ = false;
    ConnectionEnd end;
    auto reader = source_->Open([this] { return Interrupt(); });
    if (!reader.ok()) {
      end.status = reader.status();
    } else {
      end.opened = true;
      if (!RunConnection(reader->get(), &end)) return;
    }
    end.timed_out = timed_out_;
    end.session_frames = frames_;
    const std::optional<int> delay_ms = source_->AfterConnection(session_.get(), end);
    if (!delay_ms.has_value()) return;
    if (reader.ok()) reader->reset();  // close the old connection before waiting
    if (session_->WaitForStop(*delay_ms)) return EndStream(CancelledError("stopped"));
  }
}

bool SessionRunner::RunConnection(MvReader* reader, ConnectionEnd* end) {
  if (!StartConnection(reader->info())) return false;
  FrameRecord frame;
  for (;;) {
    if (end->frames > 0) SetDeadline(source_->receive_timeout_ms());
    end->status = reader->Next(&frame);
    if (!end->status.ok()) return true;
    ++end->frames;
    if (++frames_ == 1 && source_->network()) {
      session_->Transition(v1::Session::RUNNING, Status::Ok(), "receiving the stream");
    }
    if (!Feed(frame)) return false;
  }
}

bool SessionRunner::StartConnection(const StreamInfo& info) {
  if (!pipeline_.has_value()) {
    if (!MakePipeline(info)) return false;
  } else if (info.width_px != first_info_.width_px || info.height_px != first_info_.height_px ||
             info.codec_name != first_info_.codec_name) {
    EndStream(FailedPreconditionError(
        "the stream changed across a reconnect from " + first_info_.codec_name + " " +
        std::to_string(first_info_.width_px) + "x" + std::to_string(first_info_.height_px) +
        " to " + info.codec_name + " " + std::to_string(info.width_px) + "x" +
        std::to_string(info.height_px) + "; create a new session for the new stream"));
    return false;
  } else {
    // A new connection: its frames do not connect to the ones before.
    pipeline_->Break();
  }
  if (last_index_ >= 0) {
    // The new connection's frames follow the old ones, the outage's wall
    // time later (at least one frame interval).
    const double gap_s =
        std::max(std::chrono::duration<double>(Clock::now() - last_frame_wall_).count(),
                 info.fps > 0 ? 1.0 / info.fps : 1e-3);
    index_offset_ = last_index_ + 1;
    time_offset_s_ = last_timestamp_s_ + gap_s;
  }
  return true;
}

namespace {

// The session's intrinsics against the stream: the size they are for, then
// their plausibility (api::ValidateIntrinsicsForImage). A stream that does
// not know its size yet (0x0: RTP opened before its sender) is not checked.
Status CheckIntrinsicsAgainstStream(const v1::Intrinsics& pk, const StreamInfo& info) {
  if (info.width_px <= 0 || info.height_px <= 0) return Status::Ok();
  if ((pk.width_px() != 0 && pk.width_px() != info.width_px) ||
      (pk.height_px() != 0 && pk.height_px() != info.height_px)) {
    return InvalidArgumentError("intrinsics are for " + std::to_string(pk.width_px()) + "x" +
                                std::to_string(pk.height_px()) + " but the stream is " +
                                std::to_string(info.width_px) + "x" +
                                std::to_string(info.height_px));
  }
  return api::ValidateIntrinsicsForImage(pk, info.width_px, info.height_px,
                                         "intrinsics (against the stream's size)");
}

}  // namespace

bool SessionRunner::MakePipeline(const StreamInfo& info) {
  Intrinsics k;
  PipelineOptions options;
  {
    std::lock_guard<std::mutex> lock(session_->mu);
    const v1::Intrinsics& pk = session_->proto.intrinsics();
    const Status checked = CheckIntrinsicsAgainstStream(pk, info);
    if (!checked.ok()) {
      session_->TransitionLocked(v1::Session::FAILED, checked, "");
      return false;
    }
    k = api::IntrinsicsFromProto(pk);
    options = api::PipelineOptionsFromProto(session_->proto.pipeline_options());
  }
  // The stream's size when it knows it, else the intrinsics' own (if given).
  if (info.width_px > 0 && info.height_px > 0) {
    k.width_px = info.width_px;
    k.height_px = info.height_px;
  }
  pipeline_.emplace(k, info.mv_sigma_px(), options);
  first_info_ = info;
  start_ = Clock::now();
  return true;
}

bool SessionRunner::Feed(FrameRecord frame) {
  frame.index += index_offset_;
  if (frame.prev_anchor_index >= 0) frame.prev_anchor_index += index_offset_;
  if (frame.next_anchor_index >= 0) frame.next_anchor_index += index_offset_;
  if (frame.coded_index >= 0) frame.coded_index += index_offset_;
  frame.timestamp_s += time_offset_s_;
  last_index_ = frame.index;
  last_timestamp_s_ = frame.timestamp_s;
  last_frame_wall_ = Clock::now();
  received_[frame.index] = PreciseNow();
  auto step = pipeline_->Push(frame);
  if (!step.ok()) {
    EndStream(step.status());
    return false;
  }
  Publish(frame, step->has_value() ? &**step : nullptr);
  return true;
}

void SessionRunner::Publish(const FrameRecord& frame, const PipelineStep* step) {
  const double wall_s = std::chrono::duration<double>(Clock::now() - start_).count();
  std::optional<StepUpdates> updates;
  if (step != nullptr) updates = updates_.Next(*pipeline_, *step);
  std::vector<v1::SessionEvent> events;
  {
    std::lock_guard<std::mutex> lock(session_->mu);
    v1::SessionStats* st = session_->proto.mutable_stats();
    st->set_frames(frames_);
    // No figure from a blip: 0 until 10 frames or 0.25 s.
    st->set_fps(wall_s > 0 && (frames_ >= 10 || wall_s >= 0.25) ? frames_ / wall_s : 0.0);
    st->set_lag_ms(std::max(0.0, wall_s - frame.timestamp_s) * 1e3);
    st->set_stream_time_s(frame.timestamp_s);
    // Read only by a FINISHED ending without poses: not kept once there are poses
    // (the trajectory snapshot never empties again, a rescale refills it at once).
    if (session_->trajectory.empty()) session_->no_pose_reason = NoPoseReason(step);
    if (step != nullptr) {
      ++pairs_;
      tracked_ += step->tracking;
      st->set_anchor_pairs(pairs_);
      st->set_tracked_pairs(tracked_);
      st->set_planes(static_cast<int>(pipeline_->plane_map().size()));
      *session_->proto.mutable_update_time() = TimeUtil::GetCurrentTime();
      ApplyUpdatesLocked(*updates, &events);
    }
  }
  for (auto& e : events) {
    if (e.has_pose()) *e.mutable_pose()->mutable_emit_time() = PreciseNow();
    session_->events->Append(std::move(e));
  }
}

std::string SessionRunner::NoPoseReason(const PipelineStep* step) const {
  const std::string seen = std::to_string(frames_) + " frame(s)";
  if (step == nullptr && pairs_ == 0) {
    return seen + " but no anchor pair was closed (too few frames, or no two anchor frames)";
  }
  if (step != nullptr && !step->note.empty()) {
    return std::to_string(pairs_ + 1) + " anchor pair(s) but none tracked; the last: " + step->note;
  }
  if (step == nullptr) return session_->no_pose_reason;
  return std::to_string(pairs_ + 1) + " anchor pair(s) but none tracked";
}

void SessionRunner::ApplyUpdatesLocked(const StepUpdates& u,
                                       std::vector<v1::SessionEvent>* events) {
  Session& s = *session_;
  // Snapshots: a newly fixed scale rescales everything seen so far.
  if (u.rescaled) {
    s.metric = u.metric;
    s.trajectory.clear();
    s.planes.clear();
    for (const auto& [id, mp] : *u.plane_map) s.planes[id] = api::MapPlaneToProto(mp);
  }
  // The trajectory snapshot holds every posed frame: a pose of a frame it
  // holds is a revision and replaces it, others come after the last.
  for (const FramePose& p : u.frame_poses) {
    auto it = std::lower_bound(
        s.trajectory.begin(), s.trajectory.end(), p.pose.index,
        [](const v1::Trajectory::Point& q, int64_t index) { return q.anchor_index() < index; });
    if (it != s.trajectory.end() && it->anchor_index() == p.pose.index) {
      *it = api::FramePoseToPoint(p);
    } else {
      s.trajectory.push_back(api::FramePoseToPoint(p));
    }
  }

  v1::SessionEvent pose;
  v1::PoseUpdate* pu = pose.mutable_pose();
  pu->set_anchor_index(u.pose.anchor_index);
  pu->set_timestamp_s(u.pose.timestamp_s);
  *pu->mutable_world_from_cam() = api::PoseToProto(u.pose.world_from_cam);
  pu->set_tracking(u.pose.tracking);
  pu->set_metric(u.pose.metric);
  pu->set_note(u.pose.note);
  if (u.pose.tracking) *pu->mutable_quality() = api::PoseQualityToProto(u.pose.quality);
  for (const FramePose& p : u.frame_poses) *pu->add_frame_poses() = api::FramePoseToProto(p);
  auto r = received_.find(u.pose.anchor_index);
  if (r != received_.end()) *pu->mutable_frame_received_time() = r->second;
  received_.erase(received_.begin(), received_.upper_bound(u.pose.anchor_index));
  events->push_back(std::move(pose));

  for (const PlaneChange& c : u.planes) {
    s.planes[c.track_id] = api::MapPlaneToProto(*c.plane);
    v1::SessionEvent e;
    v1::PlaneEvent* pe = e.mutable_plane();
    pe->set_kind(KindToProto(c.kind));
    pe->set_track_id(c.track_id);
    *pe->mutable_normal_world() = api::Vec3ToProto(c.plane->normal_world);
    pe->set_distance(c.plane->distance_m);
    pe->set_anchor_index(c.anchor_index);
    events->push_back(std::move(e));
  }
}

}  // namespace slapse::server
