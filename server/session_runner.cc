#include "server/session_runner.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <mutex>
#include <string>
#include <vector>

#include "api/convert.h"
#include "api/validate.h"
#include "server/log.h"
#include "server/metrics.h"

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

SessionRunner::SessionRunner(std::shared_ptr<Session> session, size_t final_poses_in_memory,
                             int64_t probe_bytes)
    : session_(std::move(session)), final_poses_in_memory_(final_poses_in_memory) {
  ReaderSettings reader;
  reader.probe_bytes = probe_bytes;
  // A frame's luma only while the dashboard shows its overlays (KeepForOverlays).
  reader.luma_wanted = [overlays = session_->overlays] { return overlays->Wanted(); };
  source_ = IngestSource::Make(session_->Snapshot(), session_->upload, std::move(reader));
  std::lock_guard<std::mutex> lock(session_->mu);
  if (session_->resumed_last_index < 0) return;
  // Resumed after a restart: the counters go on, and the new pipeline's
  // frames follow the old ones on the timeline, the outage's wall time later.
  const v1::SessionStats& st = session_->proto.stats();
  frames_ = frames_before_ = st.frames();
  pairs_ = st.anchor_pairs();
  tracked_ = st.tracked_pairs();
  plane_steps_before_ = st.plane_steps();
  last_index_ = session_->resumed_last_index;
  last_timestamp_s_ = st.stream_time_s();
  const auto down = std::chrono::duration<double>(std::max(0.0, session_->resumed_down_s));
  last_frame_wall_ = Clock::now() - std::chrono::duration_cast<Clock::duration>(down);
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
  LogSessionScope log_scope(session_->name);  // FFmpeg's records name the session
  // An ended session keeps its last frame for the overlays only if a page
  // was watching then (until the session is deleted).
  struct DropOverlays {
    FrameOverlays* overlays;
    ~DropOverlays() {
      if (!overlays->Wanted()) overlays->Clear();
    }
  } drop_overlays{session_->overlays.get()};
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
  notes_reported_ = 0;
  FrameRecord frame;
  for (;;) {
    if (end->frames > 0) SetDeadline(source_->receive_timeout_ms());
    StageTimer read_timer(Stage::kRead);
    end->status = reader->Next(&frame);
    read_timer.Done();
    ReportStream(*reader, !end->status.ok());
    if (!end->status.ok()) {
      FinishConnection();
      return true;
    }
    ++end->frames;
    ++frames_;
    // A connection's first frame: RUNNING (again, after a restart's CREATED;
    // a no-op while already RUNNING).
    if (end->frames == 1 && source_->network()) {
      session_->Transition(v1::Session::RUNNING, Status::Ok(), "receiving the stream");
    }
    if (!Feed(std::move(frame))) return false;
  }
}

// Session.stream_report from the reader: on the first frame, on a new note
// (a resolution change, also said as a RUNNING state message), every 30
// frames and at the connection's end.
void SessionRunner::ReportStream(const MvReader& reader, bool at_end) {
  const ReadStats& stats = reader.stats();
  const bool new_notes = stats.notes.size() != notes_reported_;
  if (!at_end && !new_notes && stats.frames % 30 != 1) return;
  std::lock_guard<std::mutex> lock(session_->mu);
  *session_->proto.mutable_stream_report() = api::StreamReportToProto(reader.info(), stats);
  for (; notes_reported_ < stats.notes.size(); ++notes_reported_) {
    // Said as a StateChange event in the current state (Transition skips a same-state change).
    if (IsTerminal(session_->proto.state())) continue;
    session_->proto.set_state_message(stats.notes[notes_reported_]);
    v1::SessionEvent e;
    e.mutable_state_change()->set_state(session_->proto.state());
    e.mutable_state_change()->set_message(stats.notes[notes_reported_]);
    session_->events->Append(std::move(e));
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
  width_px_ = k.width_px;
  height_px_ = k.height_px;
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
  StageTimer pipeline_timer(Stage::kPipeline);
  auto step = pipeline_->Push(frame);
  pipeline_timer.Done();
  if (!step.ok()) {
    EndStream(step.status());
    return false;
  }
  const PipelineStep* done = step->has_value() ? &**step : nullptr;
  Publish(frame, done);
  KeepForOverlays(std::move(frame), done);
  return true;
}

// The connection ended: a pair the pipeline still held back for a longer
// baseline, or an IPPP chain still shorter than its minimum span, is
// processed as it is, so its frames' poses are sent too (Pipeline::Finish;
// a reconnection starts afresh anyway).
void SessionRunner::FinishConnection() {
  if (!pipeline_.has_value() || last_index_ < 0) return;
  StageTimer pipeline_timer(Stage::kPipeline);
  std::optional<PipelineStep> step = pipeline_->Finish();
  pipeline_timer.Done();
  if (!step.has_value()) return;
  FrameRecord last;
  last.index = last_index_;
  last.timestamp_s = last_timestamp_s_;
  Publish(last, &*step);
}

void SessionRunner::KeepForOverlays(FrameRecord frame, const PipelineStep* step) {
  FrameOverlays& overlays = *session_->overlays;
  if (!overlays.Wanted()) return overlays.Clear();
  if (IsAnchor(frame.type)) overlays.SetAnchor(std::move(frame), width_px_, height_px_);
  if (step != nullptr) overlays.SetPlanes(step->earlier_index, step->later_index, step->extracted);
}

void SessionRunner::Publish(const FrameRecord& frame, const PipelineStep* step) {
  StageTimer publish_timer(Stage::kPublish);
  const double wall_s = std::chrono::duration<double>(Clock::now() - start_).count();
  std::optional<StepUpdates> updates;
  if (step != nullptr) updates = updates_.Next(*pipeline_, *step);
  std::vector<v1::SessionEvent> events;
  StoreStep store_step;
  v1::Session row;
  {
    std::lock_guard<std::mutex> lock(session_->mu);
    v1::SessionStats* st = session_->proto.mutable_stats();
    st->set_frames(frames_);
    // No figure from a blip: 0 until 10 frames or 0.25 s. Only this runner's
    // frames over its own time (a resumed session's earlier ones are not).
    const int64_t run_frames = frames_ - frames_before_;
    st->set_fps(wall_s > 0 && (run_frames >= 10 || wall_s >= 0.25) ? run_frames / wall_s : 0.0);
    st->set_lag_ms(std::max(0.0, wall_s - frame.timestamp_s) * 1e3);
    st->set_stream_time_s(frame.timestamp_s);
    // Read only by a FINISHED ending without poses: not kept once there are poses
    // (the trajectory snapshot never empties again, a rescale refills it at once).
    if (session_->points == 0) session_->no_pose_reason = NoPoseReason(step);
    if (step != nullptr) {
      ++pairs_;
      tracked_ += step->tracking;
      st->set_anchor_pairs(pairs_);
      st->set_tracked_pairs(tracked_);
      const ScaleSupport support{tracked_,
                                 plane_steps_before_ + pipeline_->scale_support().plane_steps};
      st->set_plane_steps(support.plane_steps);
      st->set_scale_support_weak(support.Weak());
      st->set_planes(
          static_cast<int>(pipeline_->planes_forgotten() + pipeline_->plane_map().size()));
      *session_->proto.mutable_update_time() = TimeUtil::GetCurrentTime();
      ApplyUpdatesLocked(*updates, &events, &store_step);
      row = session_->proto;
      store_step.metric = session_->metric;
    }
  }
  // The step's updates are in `events` and `store_step` now: the pipeline may
  // forget what is final (the store keeps it), so a session's memory does not
  // grow with its length.
  if (step != nullptr) pipeline_->ForgetFinal(final_poses_in_memory_);
  if (events.empty()) return;
  for (auto& e : events) {
    if (e.has_pose()) *e.mutable_pose()->mutable_emit_time() = PreciseNow();
  }
  // The step's points, planes, session row and events in one transaction,
  // before watchers can see the events (server/store.h).
  session_->events->AppendBatch(std::move(events), [&](const std::vector<v1::SessionEvent>& batch) {
    row.set_last_sequence(batch.back().sequence());
    store_step.session = &row;
    session_->CommitStep(store_step, batch);
  });
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

void SessionRunner::ApplyUpdatesLocked(const StepUpdates& u, std::vector<v1::SessionEvent>* events,
                                       StoreStep* step) {
  Session& s = *session_;
  step->segment = s.segment;
  // Snapshots: a newly fixed scale rescales everything seen so far (of this
  // segment: the pipeline's own).
  if (u.rescaled) {
    s.metric = u.metric;
    step->replace_points = true;
    step->replace_planes = true;
    s.points -= segment_points_;
    segment_points_ = 0;
    last_point_index_ = -1;  // every pose comes again
    for (const auto& [id, mp] : *u.plane_map) {
      step->planes.push_back(api::MapPlaneToProto(mp));
      step->planes.back().set_segment(s.segment);
    }
  }
  // The trajectory snapshot holds every posed frame (Pipeline::poses()): a
  // pose of a frame already stored is a revision and replaces it in place
  // (Store::CommitStep updates the row of the same segment and frame index);
  // new frames come in display order after the last one stored.
  for (const FramePose& p : u.frame_poses) {
    step->points.push_back(api::FramePoseToPoint(p));
    step->points.back().set_segment(s.segment);
    if (p.pose.index > last_point_index_) {
      last_point_index_ = p.pose.index;
      ++s.points;
      ++segment_points_;
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
  pu->set_scale_note(u.pose.scale_note);
  pu->set_extended(u.pose.extended);
  if (u.pose.tracking) *pu->mutable_quality() = api::PoseQualityToProto(u.pose.quality);
  for (const FramePose& p : u.frame_poses) *pu->add_frame_poses() = api::FramePoseToProto(p);
  auto r = received_.find(u.pose.anchor_index);
  if (r != received_.end()) *pu->mutable_frame_received_time() = r->second;
  // An extended pair's anchor is posed by a later step (Pipeline::Finish
  // may bring that same anchor again): its time is kept.
  received_.erase(received_.begin(), u.pose.extended ? received_.lower_bound(u.pose.anchor_index)
                                                     : received_.upper_bound(u.pose.anchor_index));
  events->push_back(std::move(pose));

  for (const PlaneChange& c : u.planes) {
    step->planes.push_back(api::MapPlaneToProto(*c.plane));
    step->planes.back().set_segment(s.segment);
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
