// The SLAPSE pipeline in streaming form: frame records in (display order),
// one step per anchor pair out. Stages (paper Sec. V-VI, docs/METHOD.md):
//   FrontEnd (SegmentMerger -> pair motion + ThresholdInfinity ->
//   PlaneExtractor, core/pipeline/front_end.h) -> PlaneEkf.
// No stage buffers more than one GOP segment, so the service can run it live.
//
// Frames: the world frame is the camera frame of the first anchor the filter
// was initialised on (x right, y down, z forward); poses are world_from_cam
// (x_world = R x_cam + t). Lengths are in units of the first step unless a
// scale source makes them metres.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"
#include "core/common/timed_pose.h"
#include "core/ekf/plane_ekf.h"
#include "core/estimators/road_step.h"
#include "core/merge/mv_merge.h"
#include "core/mv/frame_record.h"
#include "core/pipeline/frame_poses.h"
#include "core/pipeline/front_end.h"
#include "core/planes/infinity.h"
#include "core/planes/plane_extraction.h"
#include "core/refine/window_refiner.h"

namespace slapse {

// Where the metric scale comes from (monocular: otherwise up to scale).
struct ScaleOptions {
  enum class Source { kUpToScale, kFirstStep, kSpeed, kCameraHeight };
  // kUpToScale: the first tracked step has length 1 (as the paper).
  Source source = Source::kUpToScale;
  // kFirstStep: length of the first tracked step, m.
  double first_step_m = 1.0;
  // kSpeed: the vehicle's speed at initialisation, m/s.
  double speed_mps = 0.0;
  // kCameraHeight: the camera's height above the road plane, m. The scale is
  // fixed when a filter plane that is road-like (core/common/road.h: normal
  // within road_max_angle_deg of the camera's down axis, below the camera)
  // has been tracked for `road_min_observations` updates.
  double camera_height_m = 0.0;
  int road_min_observations = 5;
  double road_max_angle_deg = 25.0;
  // With the window refiner (PipelineOptions::window_refine) the height is
  // read from the road plane refined jointly over the window, once at least
  // this many of the window's pairs observed it -- or from the filter's road
  // once it has been measured (by a pair, or by its step in the B frames)
  // on this many steps in a row and `road_min_observations` times in all;
  // until then the step's scale_note says the metric scale is not
  // observable yet.
  int road_min_window_pairs = 3;
  // kCameraHeight: stream seconds after the first pose within which the road
  // must fix the scale. Past it the run stays up to scale for good (the
  // step's scale_note says so) and the scale can no longer change, so a long
  // run can forget its final results (Pipeline::ForgetFinal). 0: no deadline.
  double road_deadline_s = 60.0;
  // kCameraHeight: the road places the height well only when the camera sees
  // it steeply enough: the fix reports the steepest ray of the image to the
  // road, as its angle below the road's horizon (core/common/road.h
  // SteepestRoadDepressionDeg; Pipeline::height_road_depression_deg), and
  // calls the metric scale weak below this. Not an option: a fact of the
  // measurements, chosen on the tuning drives (8 of their 15 runs below it
  // beyond 3 %, 11 of 69 above). On all 161 metric runs of both profiles
  // and splits: beyond 3 % on 19 of the 31 runs below 18 deg (1242x376
  // frames, 30 deg of vertical field, the camera level or pitched up), on
  // 22 of the 130 above (docs/TRAJECTORY.md "Session 28").
  static constexpr double kMinRoadDepressionDeg = 18.0;
  // The rule: a camera-height scale fixed from a road seen at most
  // `road_depression_deg` below its horizon is weak (NaN, no road: weak).
  static bool HeightScaleWeak(double road_depression_deg) {
    return !(road_depression_deg >= kMinRoadDepressionDeg);
  }
};

// The front end's options (merge, infinity, extraction) and the filter's.
struct PipelineOptions : FrontEndOptions {
  EkfOptions ekf;
  ScaleOptions scale;
  // Initialise only on a pair with motion and at least this many planes
  // (unless motion_only_steps).
  int min_planes_to_initialise = 1;
  // Adaptive baseline while waiting to initialise (docs/METHOD.md, the
  // section of that name; wire: PipelineOptions.init_max_baseline_s, flag
  // --init-max-baseline-s): a pair without reliable motion because
  // its baseline is too short (BaselineTooShort: its vectors with parallax
  // agree with its essential matrix, but do not triangulate within the depth
  // bound) and whose anchors are less than this apart is not dropped; the
  // next one-frame P segment is composed onto it (FrontEnd::ExtendBaseline),
  // so at 60 fps or car-park speed the baseline grows frame by frame until
  // the parallax decides the motion. B-frame segments are never extended.
  // 0: off.
  double init_max_baseline_s = 0.5;
  // The same while tracking (docs/METHOD.md "Adaptive baseline while
  // tracking"; wire: PipelineOptions.track_max_baseline_s, flag
  // --track-max-baseline-s): such a pair is handed back instead of coasting
  // on the motion model; the filter waits for the longer pair, whose step
  // covers both frames (the frame between is posed with it). 0: off.
  double track_max_baseline_s = 0.5;
  // Motion-only steps (docs/METHOD.md "Motion-only steps"): a pair with
  // reliable motion but no plane observed still tracks. It initialises the
  // filter (no planes needed), and where no tracked plane is observed the
  // filter takes the pair's epipolar rotation and direction of travel
  // (PlaneEkf::UpdateMotion) instead of only predicting; the step length is
  // the motion model's. Such anchors are PoseKind::kMotionOnly. Off: such
  // pairs wait ("no plane extracted") or coast, as the paper's method does.
  bool motion_only_steps = true;
  // The road from the frames between the anchors (docs/METHOD.md, the
  // section of that name; wire: PipelineOptions.road_from_frames, flag
  // --road-from-frames). In a stream with B frames, a step that observed no
  // road (the anchors' vectors lost it: at speed the near road moves beyond
  // the encoder's search over the anchor span) measures it from the past
  // vectors of the B frames in the first kRoadFromFramesMaxFraction of the
  // pair (core/estimators/road_step.h): the step length over the road's
  // distance updates the kept road and the step (PlaneEkf::UpdateRoadStep),
  // or the road joins the filter where it has none
  // (PlaneEkf::AddRoadFromStep). Off: such steps coast on the motion model.
  bool road_from_frames = true;
  RoadStepOptions road_step;
  // Poses of the frames between anchors (core/pipeline/frame_poses.h).
  FramePoserOptions frame_poses;
  // Sliding-window refinement of the last anchors' poses and the planes they
  // see (core/refine, docs/METHOD.md "Windowed refinement"), the EKF as its
  // predictor. Off: the EKF's poses as they are.
  bool window_refine = true;
  WindowRefinerOptions refine;
  // How many of the latest poses stay revisable after a step
  // (Pipeline::first_revisable_pose); 0: every pose is final once reported.
  // A window refiner sets it to cover its window.
  int revisable_tail_poses = 0;
};

// A plane as the map holds it: world frame, with its history.
struct MapPlane {
  int track_id = -1;
  Eigen::Vector3d normal_world = Eigen::Vector3d::UnitZ();  // unit, n . X = d
  double distance_m = 0.0;  // in the trajectory's length unit (metres if metric)
  Eigen::Vector3d pi_cam = Eigen::Vector3d::Zero();     // n / d in the camera of last_seen
  int64_t first_seen_index = -1, last_seen_index = -1;  // anchor display indices
  double first_seen_s = 0.0, last_seen_s = 0.0;
  int observations = 0;
  std::vector<int64_t> seen_indices;  // anchors where the filter held it
  std::vector<int> mb_indices;        // cells of the last anchor it was seen in
  // Extent in the world: the plane points of its macroblocks, accumulated.
  std::vector<Eigen::Vector3d> support_world;
};

// Wall-clock cost of each stage for one anchor pair, milliseconds.
struct StageTimes : FrontEndTimes {
  double ekf_ms = 0;
  double frame_poses_ms = 0;  // posing the frames between the anchors
  double refine_ms = 0;
};

struct PipelineStep {
  int64_t earlier_index = -1, later_index = -1;  // the anchor pair
  double timestamp_s = 0.0;                      // of the later anchor
  SegmentType segment = SegmentType::kPP;
  bool tracking = false;              // the filter is running (pose and planes valid)
  bool metric = false;                // lengths are metres
  Rigid3d world_from_cam;             // pose of the later anchor
  int correspondences = 0, kept = 0;  // merged MBs, and those with parallax
  // How the pair's motion was found (kNone also when the estimate failed).
  PairMotionPath motion_path = PairMotionPath::kNone;
  std::vector<ExtractedPlane> extracted;  // this pair's planes (MB sets, homographies)
  // Per extracted plane: the track id of the filter plane it is an
  // observation of (its own id, or the road's when the filter re-identified
  // it as the road; PlaneEkf::FilterTrackId). The one bridge between the two
  // identities a plane has (docs/METHOD.md "Where each rule lives"): the
  // extractor's track id (MB sets followed from pair to pair) and the
  // filter's (which merges re-found road tracks into one plane and splits a
  // track that fails the association gate).
  std::vector<int> extracted_filter_ids;
  // The filter's planes after this step (n / d in the later anchor's camera).
  std::vector<PlaneTrack> planes;
  UpdateReport ekf;
  // The window refiner's solve (solved = false when it is off or did not run).
  // world_from_cam is the refined pose of the newest anchor; earlier poses in
  // trajectory() are not revised (final once emitted, as clients saw them).
  WindowRefineReport refine;
  // Whether the metric scale is observable (empty up to scale): e.g. "metric:
  // camera height 1.50 m over the road seen in 5 of 5 window pairs" or
  // "metric scale not observable yet: ...".
  std::string scale_note;
  StageTimes times;
  std::string note;  // why the step did not track, if it did not
  // Too short a baseline: the pair was handed back to the front end and the
  // next one-frame P pair extends it (init_max_baseline_s,
  // track_max_baseline_s); tracking is false, and this pair's frames are
  // posed with the next step.
  bool extended = false;
  // The filter (re)started on this pair without a plane (motion_only_steps).
  bool motion_only_start = false;
  // No plane carried this step, the pair's own motion did (a MOTION_ONLY
  // anchor): the filter started on it without a plane, or took its motion.
  bool motion_only() const { return motion_only_start || ekf.motion_updated; }
  // The all-frames poses this step added, in display order: when tracking,
  // the frames between the anchors and the later anchor (and the earlier
  // anchor when the trajectory (re)starts on it); see Pipeline::poses().
  std::vector<FramePose> frame_poses;
};

// A run's anchor pairs, each counted once: when the step Pipeline::Finish
// returns is the pair the last extended step handed back (same anchors), it
// replaces that one; a flushed IPPP chain is a pair of its own (`run` and
// the trajectory evaluation report these counts).
struct PipelineStepCounts {
  int pairs = 0, tracked = 0, extended = 0;
  // A step of Pipeline::Push.
  void Add(const PipelineStep& step) {
    ++pairs;
    tracked += step.tracking;
    extended += step.extended;
    last_extended_ = step.extended ? std::optional(std::pair(step.earlier_index, step.later_index))
                                   : std::nullopt;
  }
  // The step of Pipeline::Finish.
  void AddFinish(const PipelineStep& step) {
    if (last_extended_ == std::pair(step.earlier_index, step.later_index)) {
      --pairs;
      --extended;
    }
    Add(step);
  }

 private:
  // The anchors of the last step added, if it was extended.
  std::optional<std::pair<int64_t, int64_t>> last_extended_;
};

class Pipeline {
 public:
  // sigma_px: the stream's MV error (StreamInfo::mv_sigma_px()).
  Pipeline(const Intrinsics& intrinsics, double sigma_px, PipelineOptions options = {});

  // Feeds the next frame. Returns a step when the frame closed an anchor pair.
  // Errors are for broken contracts only (e.g. frames out of order); a pair
  // that cannot be used yields a step with tracking = false and a note.
  StatusOr<std::optional<PipelineStep>> Push(const FrameRecord& frame);

  // The stream broke off (e.g. a network source reconnected): the frames
  // pushed next do not connect to those before. Drops the open GOP segment,
  // the remembered planes and the filter; the trajectory, plane map and scale
  // stay. The filter re-initialises on the next usable pair from the last
  // pose, at the last step's speed as scale (as after a filter reset).
  // Later frames still need larger indices and timestamps.
  void Break();

  // The stream ended (or broke off): a pair that was handed back for a
  // longer baseline while tracking (track_max_baseline_s) and that no later
  // frame extended, or else an IPPP chain still shorter than
  // MergeOptions::min_pair_span_s, is processed as it is, so that its frames
  // get their poses; then as Break(). Returns that pair's step (nullopt:
  // none was pending). Without it the last frames of such a stream stay
  // unposed.
  std::optional<PipelineStep> Finish();

  // Pose numbers: the n-th pose of the run (0-based, in display order) has
  // number n for good. Without ForgetFinal poses()[n] is pose n; after it
  // poses()[k] is pose poses_forgotten() + k, and likewise for trajectory()
  // and anchors_forgotten().
  //
  // The anchors' poses (one per tracked anchor; those not forgotten).
  const std::vector<TimedPose>& trajectory() const { return trajectory_; }
  // Every posed frame in display order, anchors included, with its quality
  // (the trajectory `run` writes and the service reports; those not forgotten).
  const std::vector<FramePose>& poses() const { return poses_; }
  // Pose numbers >= this may still be revised (RevisePose); those before are
  // final. Never decreases. After each step it is the number of poses so far
  // minus revisable_tail_poses (or where it was, if later).
  size_t first_revisable_pose() const { return first_revisable_pose_; }
  // Replaces pose number n's pose (e.g. a window refinement moved an anchor,
  // and with it the frames between): its revision goes up, an anchor's entry
  // in trajectory() follows, and UpdateStream sends it again.
  // FAILED_PRECONDITION for a final pose (n < first_revisable_pose()),
  // OUT_OF_RANGE past the last pose.
  Status RevisePose(size_t n, const Rigid3d& world_from_cam);
  // Every plane the filter ever held, by track id (those not forgotten).
  const std::map<int, MapPlane>& plane_map() const { return plane_map_; }
  bool metric() const { return metric_; }
  // kCameraHeight, once metric: the steepest ray of the image to the road
  // the scale was fixed from, degrees below the road's horizon
  // (ScaleOptions::kMinRoadDepressionDeg); nullopt before (or for another source).
  std::optional<double> height_road_depression_deg() const { return height_road_depression_deg_; }
  // How many of the tracked anchor steps a plane observation measured
  // (ScaleSupport), over the whole run.
  const ScaleSupport& scale_support() const { return scale_support_; }

  // Bounded memory for runs of any length (the service, whose store keeps
  // the results): drops the final poses but the last `keep_final_poses`,
  // the anchors before the first pose kept (the last two always stay), and
  // the map planes the filter no longer holds that were last seen before the
  // first anchor kept. Call it only once the last step's updates were taken
  // (UpdateStream::Next) and used: what it drops is gone. It drops nothing
  // while ScaleMayChange(), since fixing the scale rescales and re-sends
  // everything seen so far.
  void ForgetFinal(size_t keep_final_poses);
  size_t poses_forgotten() const { return poses_forgotten_; }
  size_t anchors_forgotten() const { return anchors_forgotten_; }
  size_t planes_forgotten() const { return planes_forgotten_; }
  // Whether a later step may still fix the metric scale (kCameraHeight, not
  // metric yet, its road_deadline_s not passed).
  bool ScaleMayChange() const;

 private:
  PipelineStep Process(const FrontEndStep& front);
  // Starts the filter on the step's pair (waiting or failing sets step->note).
  void Initialise(const FrontEndStep& front, const std::vector<PlaneObservation>& observations,
                  double dt_s, PipelineStep* step);
  // Whether the running filter skips this pair for a longer one
  // (track_max_baseline_s); true: the front end extends it.
  bool ExtendWhileTracking(const FrontEndStep& front, double dt_s);
  // Predicts and updates the running filter (a numerical failure resets it).
  void Advance(const FrontEndStep& front, const std::vector<PlaneObservation>& observations,
               double dt_s, PipelineStep* step);
  // PipelineOptions::road_from_frames for a step whose update observed no
  // road: the B frames within kRoadFromFramesMaxFraction of the pair's span
  // after its earlier anchor (B1 and B2 of IBBBP: one- and two-frame
  // vectors) measure it. A road added so takes the track id
  // kRoadFromFramesTrackId + the number added before (extraction numbers
  // its planes from 0). Errors are the filter's numerical failures.
  static constexpr double kRoadFromFramesMaxFraction = 0.55;
  static constexpr int kRoadFromFramesTrackId = 1 << 30;
  Status UpdateRoadFromFrames(const FrontEndStep& front, UpdateReport* report);
  // The first step's length when the filter starts: on re-initialisation the
  // last step's speed times dt_s, else from the scale source (may set metric_).
  double InitialStepLength(double dt_s);
  // A new filter and an empty window: the next usable pair re-initialises.
  void ResetFilter();
  static bool IsFinite(const Rigid3d& pose);
  // A step whose pose came out non-finite (a numerical failure the filter or
  // refiner did not report) does not track: the pose goes back to
  // `world_from_cam_before` and the filter restarts on a later pair, as
  // after a reported failure -- never a NaN pose passed on as tracked.
  void RestartOnNonFinite(const Rigid3d& world_from_cam_before, PipelineStep* step);
  void RecordPlanes(const PipelineStep& step, const AnchorPair& pair);
  void ApplyScale(double s);
  // kCameraHeight: the scale fixed by a road at the given height (every
  // source of it): ApplyScale(s), the window's road held at the metric
  // camera height (WindowRefiner::SetRoadHeight; unused without the
  // refiner), and the run metric from now on.
  void FixScaleFromHeight(double s);
  void MaybeFixScaleFromRoad(PipelineStep* step);
  // kCameraHeight, the scale just fixed from the road `road_pi_cam` (the
  // newest camera's): records how steeply the image saw it and says so in
  // the step's scale_note, after `how` ("camera height over ...").
  void NoteHeightFix(const Eigen::Vector3d& road_pi_cam, const std::string& how,
                     PipelineStep* step);
  // Appends the step's all-frames poses (the frames between its anchors, the
  // later anchor, and the earlier one where the trajectory (re)starts).
  void AddFramePoses(const AnchorPair& pair, PipelineStep* step);
  PoseQuality AnchorQuality(const PipelineStep& step) const;
  // The window refiner's hook: adds the step's anchor and observations,
  // solves, and takes the refined poses (the EKF is rescaled to the refined
  // step, so it predicts at the window's scale).
  void RefineWindow(const AnchorPair& pair, PipelineStep* step);
  // kCameraHeight with the refiner: the scale from the window's road plane.
  void MaybeFixScaleFromWindowRoad(PipelineStep* step);
  // kCameraHeight with the refiner, where the window does not see the road
  // in enough pairs (MPEG-2 at 10 fps: the anchor pairs rarely extract it):
  // the scale from the filter's road once it has been measured -- by a
  // pair's update or by its step in the B frames -- on
  // road_min_window_pairs steps in a row. Counts the steps; true if fixed.
  bool MaybeFixScaleFromMeasuredRoad(PipelineStep* step);

  Intrinsics intrinsics_;
  PipelineOptions options_;
  FrontEnd front_end_;
  PlaneEkf ekf_;
  WindowRefiner refiner_;
  int64_t last_index_ = -1;
  std::optional<FrontEndStep> handed_back_;  // ExtendWhileTracking's pair, until the next one
  bool finishing_ = false;                   // in Finish: no more extensions
  Rigid3d world_from_cam_;
  bool metric_ = false;
  int road_measured_steps_ = 0;  // MaybeFixScaleFromMeasuredRoad's run of steps
  std::optional<double> height_road_depression_deg_;
  std::vector<TimedPose> trajectory_;
  ScaleSupport scale_support_;
  std::map<int, MapPlane> plane_map_;
  FramePoser frame_poser_;
  std::vector<FramePose> poses_;
  size_t first_revisable_pose_ = 0;
  size_t poses_forgotten_ = 0, anchors_forgotten_ = 0, planes_forgotten_ = 0;
  double first_pose_s_ = -1.0;   // the first tracked anchor's time (-1: none yet)
  bool scale_given_up_ = false;  // kCameraHeight: road_deadline_s passed while up to scale
  int roads_from_frames_ = 0;    // roads added by UpdateRoadFromFrames (their track ids)
};

}  // namespace slapse
