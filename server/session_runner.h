// SessionRunner: runs one session on a worker thread, from its first
// connection to its end. Per connection it opens the source's reader under
// the source's deadlines, makes the Pipeline on the first one (checking the
// intrinsics against the stream), splices later connections onto one
// timeline (indices and timestamps continue, the pipeline Breaks), feeds the
// frames, and turns each step's UpdateStream updates (core/pipeline/
// update_stream.h) into the session's stats, snapshots and events (wire
// messages via api/convert.h). How a connection's end reads is the source's
// business (server/ingest_source.h).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>

#include <google/protobuf/timestamp.pb.h>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "core/pipeline/update_stream.h"
#include "server/ingest_source.h"
#include "server/session.h"

namespace slapse::server {

class SessionRunner {
 public:
  // final_poses_in_memory: SessionManagerOptions's (Pipeline::ForgetFinal).
  // probe_bytes: SessionManagerOptions::reader_probe_bytes (MvReaderOptions::probe_bytes).
  SessionRunner(std::shared_ptr<Session> session, size_t final_poses_in_memory,
                int64_t probe_bytes = 0);
  // Runs the session to its end (a terminal state).
  void Run();

 private:
  using Clock = std::chrono::steady_clock;

  // The reader's interrupt: the session was asked to stop, or a network
  // source's deadline passed (then timed_out_).
  bool Interrupt();
  void SetDeadline(int ms);
  // Reads connection `reader` to its end into `end`; false if the session
  // ended inside it.
  bool RunConnection(MvReader* reader, ConnectionEnd* end);
  void ReportStream(const MvReader& reader, bool at_end);
  // First connection: makes the pipeline; later ones: checks the stream is
  // the same and breaks the pipeline. Then continues the timeline. False if
  // the session ended.
  bool StartConnection(const StreamInfo& info);
  bool MakePipeline(const StreamInfo& info);
  // Puts `frame` on the session's timeline, runs it through the pipeline and
  // publishes the result; false if the session ended.
  bool Feed(FrameRecord frame);
  // At a connection's end: the pipeline's held-back pair, published (Pipeline::Finish).
  void FinishConnection();
  void Publish(const FrameRecord& frame, const PipelineStep* step);
  // The dashboard's overlays (server/frame_overlays.h): an anchor frame and
  // the step's planes, kept only while someone asks for them.
  void KeepForOverlays(FrameRecord frame, const PipelineStep* step);
  // Why the session has no poses yet, after `step` (null: a frame that
  // closed no pair). Called before the step is counted.
  std::string NoPoseReason(const PipelineStep* step) const;
  // With the session's lock held: the snapshots and the events of a step.
  // With the session's lock held: the step's events and what it writes to
  // the store.
  void ApplyUpdatesLocked(const StepUpdates& updates, std::vector<v1::SessionEvent>* events,
                          StoreStep* step);
  // Ends the session after its stream broke off with `status`.
  void EndStream(const Status& status);

  const std::shared_ptr<Session> session_;
  const size_t final_poses_in_memory_;
  std::unique_ptr<IngestSource> source_;
  std::atomic<int64_t> deadline_ns_{0};
  std::atomic<bool> timed_out_{false};

  std::optional<Pipeline> pipeline_;
  UpdateStream updates_;
  StreamInfo first_info_;
  Clock::time_point start_;                                  // when the pipeline was made
  std::map<int64_t, google::protobuf::Timestamp> received_;  // frame index -> when read
  int64_t frames_ = 0;                                       // over the session's life
  int64_t frames_before_ = 0;  // of frames_, decoded before a restart (not by this runner)
  size_t notes_reported_ = 0;  // the connection's reader notes already in stream_report
  int64_t pairs_ = 0, tracked_ = 0;
  // A resumed session's plane_steps before this runner's pipeline (whose
  // ScaleSupport counts its own steps only).
  int64_t plane_steps_before_ = 0;
  int64_t index_offset_ = 0;       // added to a connection's frame indices
  double time_offset_s_ = 0.0;     // and to its timestamps
  int64_t last_index_ = -1;        // of the last frame processed (offset)
  double last_timestamp_s_ = 0.0;  // of the last frame processed (offset)
  Clock::time_point last_frame_wall_;
  int64_t segment_points_ = 0;        // trajectory points of this run's pipeline
  int64_t last_point_index_ = -1;     // frame index of the last trajectory point stored
  int width_px_ = 0, height_px_ = 0;  // the pipeline's image size (the overlays')
};

}  // namespace slapse::server
