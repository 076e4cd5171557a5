#include "core/pipeline/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <utility>

#include "core/common/plane.h"
#include "core/common/road.h"
#include "core/common/timing.h"
#include "core/estimators/road_step.h"

namespace slapse {
namespace {

constexpr size_t kMaxSupportPointsPerPlane = 4000;

// The filter's observations: per extracted plane, its correspondences.
std::vector<PlaneObservation> ObservationsOf(const AnchorPair& pair,
                                             const std::vector<ExtractedPlane>& extracted) {
  std::vector<PlaneObservation> observations;
  for (const ExtractedPlane& plane : extracted) {
    PlaneObservation obs;
    obs.track_id = plane.track_id;
    for (int i : plane.correspondence_indices) {
      const Correspondence& c = pair.correspondences[i];
      obs.x_later_px.push_back(c.x_later_px);
      obs.x_earlier_px.push_back(c.x_earlier_px);
      obs.variance_px2.push_back(c.variance_px2);
    }
    observations.push_back(std::move(obs));
  }
  return observations;
}

// A pair without motion whose baseline is too short for its depths, rather
// than one whose vectors are wrong: at least half of the vectors off the
// rotation-only model (by tau_inf) are inliers of the pair's essential
// matrix, yet too few triangulate in front within recoverPose's 50-baseline
// depth bound (a car park at 60 fps). Where most such vectors miss the
// essential matrix (a fast drive whose near-road vectors exceed the search
// range) a longer baseline only makes them worse. No vector off the
// rotation-only model (a still camera): too short as well.
bool BaselineTooShort(const PairMotionReport& motion) {
  if (motion.has_motion) return false;
  return motion.num_parallax_inliers * 2 >= motion.num_rotation_outliers;
}

// The one test of both baseline extensions (init_max_baseline_s,
// track_max_baseline_s): `front`'s pair, dt_s long, is too short for its
// parallax and shorter than max_s, and the front end took it back to extend it.
bool HandBack(FrontEnd* front_end, const FrontEndStep& front, double dt_s, double max_s) {
  return front.infinity.ok() && BaselineTooShort(*front.infinity) && dt_s < max_s &&
         front_end->ExtendBaseline(front.pair);
}

// The frame poser's options: it keeps the frames for the road from the
// frames too, with or without frame poses.
FramePoserOptions FramePoserFor(const PipelineOptions& options) {
  FramePoserOptions o = options.frame_poses;
  o.keep_frames = o.keep_frames || options.road_from_frames;
  return o;
}

}  // namespace

bool Pipeline::ExtendWhileTracking(const FrontEndStep& front, double dt_s) {
  if (finishing_ || !HandBack(&front_end_, front, dt_s, options_.track_max_baseline_s)) {
    return false;
  }
  handed_back_ = front;
  return true;
}

Pipeline::Pipeline(const Intrinsics& intrinsics, double sigma_px, PipelineOptions options)
    : intrinsics_(intrinsics),
      options_(options),
      front_end_(intrinsics, sigma_px, options),
      ekf_(intrinsics, options.ekf),
      refiner_(intrinsics, options.refine),
      frame_poser_(intrinsics, sigma_px, FramePoserFor(options)) {}

StatusOr<std::optional<PipelineStep>> Pipeline::Push(const FrameRecord& frame) {
  if (frame.index <= last_index_) {
    return InvalidArgumentError("frame " + std::to_string(frame.index) + " after frame " +
                                std::to_string(last_index_) +
                                ": frames must come in display order");
  }
  last_index_ = frame.index;
  frame_poser_.Buffer(frame);
  std::optional<FrontEndStep> front = front_end_.Push(frame);
  if (!front.has_value()) return std::optional<PipelineStep>();
  handed_back_.reset();  // extended by this pair, or given up
  return std::optional<PipelineStep>(Process(*front));
}

std::optional<PipelineStep> Pipeline::Finish() {
  // A handed-back pair holds the merger's open chain; otherwise the chain
  // shorter than min_pair_span_s, if any, is flushed.
  std::optional<FrontEndStep> last =
      handed_back_.has_value() ? std::move(handed_back_) : front_end_.Flush();
  std::optional<PipelineStep> step;
  if (last.has_value()) {
    finishing_ = true;
    step = Process(*last);
    finishing_ = false;
  }
  Break();
  return step;
}

void Pipeline::Break() {
  handed_back_.reset();
  front_end_.Reset();
  frame_poser_.Reset();
  ResetFilter();
}

void Pipeline::ResetFilter() {
  ekf_ = PlaneEkf(intrinsics_, options_.ekf);
  refiner_.Reset();
  road_measured_steps_ = 0;
}

PipelineStep Pipeline::Process(const FrontEndStep& front) {
  const AnchorPair& pair = front.pair;
  PipelineStep step;
  step.earlier_index = pair.earlier_index;
  step.later_index = pair.later_index;
  step.timestamp_s = pair.later_timestamp_s;
  step.segment = pair.type;
  step.correspondences = static_cast<int>(pair.correspondences.size());
  static_cast<FrontEndTimes&>(step.times) = front.times;
  // A failed motion or extraction: the filter goes on without planes.
  step.kept = front.infinity.ok() ? static_cast<int>(front.infinity->kept_indices.size()) : 0;
  if (front.infinity.ok()) step.motion_path = PairMotionPathOf(*front.infinity);
  if (front.extraction.ok()) step.extracted = front.extraction->planes;
  const std::vector<PlaneObservation> observations = ObservationsOf(pair, step.extracted);
  const double dt_s = pair.later_timestamp_s - pair.earlier_timestamp_s;

  const auto t0 = std::chrono::steady_clock::now();
  const Rigid3d world_from_cam_before = world_from_cam_;
  bool extend_baseline = false;
  if (!(dt_s > 0)) {
    step.note = "anchor timestamps do not increase";
  } else if (!ekf_.initialized()) {
    Initialise(front, observations, dt_s, &step);
    extend_baseline =
        !step.tracking && HandBack(&front_end_, front, dt_s, options_.init_max_baseline_s);
  } else if (ExtendWhileTracking(front, dt_s)) {
    // The filter stays at the earlier anchor; its planes are unchanged.
    extend_baseline = true;
    step.note =
        "baseline too short: extended by the next frame, which this pair's frames are "
        "posed with";
    step.planes = ekf_.planes();
    step.world_from_cam = world_from_cam_;
  } else {
    Advance(front, observations, dt_s, &step);
  }
  step.times.ekf_ms = MsSince(t0);
  if (step.tracking && !IsFinite(world_from_cam_)) RestartOnNonFinite(world_from_cam_before, &step);
  if (step.tracking) {
    for (const ExtractedPlane& ex : step.extracted) {
      step.extracted_filter_ids.push_back(ekf_.FilterTrackId(ex.track_id));
    }
    if (options_.window_refine && step.motion_only()) {
      // No plane to refine against: the window restarts when planes return.
      refiner_.Reset();
    } else if (options_.window_refine) {
      const auto t1 = std::chrono::steady_clock::now();
      RefineWindow(pair, &step);
      step.times.refine_ms = MsSince(t1);
      if (!IsFinite(world_from_cam_)) RestartOnNonFinite(world_from_cam_before, &step);
    }
  }
  if (step.tracking) {
    trajectory_.push_back({pair.later_index, pair.later_timestamp_s, world_from_cam_});
    if (first_pose_s_ < 0) first_pose_s_ = pair.earlier_timestamp_s;
    RecordPlanes(step, pair);
    if (ScaleMayChange()) {
      if (options_.window_refine) {
        MaybeFixScaleFromWindowRoad(&step);
      } else {
        MaybeFixScaleFromRoad(&step);
      }
      const double deadline_s = options_.scale.road_deadline_s;
      if (!metric_ && deadline_s > 0 && pair.later_timestamp_s - first_pose_s_ > deadline_s) {
        scale_given_up_ = true;
        step.scale_note = "metric scale not observable: no road plane fixed it within " +
                          std::to_string(static_cast<int>(deadline_s)) +
                          " s of the first pose (road_deadline_s); the trajectory stays up to "
                          "scale";
      }
    }
    step.world_from_cam = world_from_cam_;
    step.planes = ekf_.planes();
    const auto t1 = std::chrono::steady_clock::now();
    AddFramePoses(pair, &step);
    step.times.frame_poses_ms = MsSince(t1);
  } else if (extend_baseline) {
    // The frames after the earlier anchor are inside the extended pair.
    step.extended = true;
    frame_poser_.Skip(pair.earlier_index);
  } else {
    frame_poser_.Skip(pair.later_index);
  }
  // Poses before first_revisable_pose_ are final (it never decreases); the
  // last revisable_tail_poses stay open (0: none; the window refiner does not
  // revise emitted poses, see RefineWindow).
  const size_t tail = static_cast<size_t>(std::max(0, options_.revisable_tail_poses));
  const size_t posed = poses_forgotten_ + poses_.size();
  first_revisable_pose_ = std::max(first_revisable_pose_, posed - std::min(tail, posed));
  step.metric = metric_;
  return step;
}

double Pipeline::InitialStepLength(double dt_s) {
  const ScaleOptions& sc = options_.scale;
  double length = 1.0;  // up to scale
  if (trajectory_.size() >= 2) {
    // Re-initialisation: the last step's speed over this pair's time, so the
    // scale carries over whatever the two pairs' spans (an IBBBP GOP's last
    // pair may span 3 frames and the next 4: its length alone would shrink
    // the scale by 3/4 at every restart).
    const TimedPose& a = trajectory_[trajectory_.size() - 2];
    const TimedPose& b = trajectory_.back();
    const double last_dt_s = b.timestamp_s - a.timestamp_s;
    const double last_length = (b.world_from_cam.translation - a.world_from_cam.translation).norm();
    length = last_dt_s > 0 ? last_length / last_dt_s * dt_s : last_length;
    length = std::max(length, 1e-6);
  } else if (sc.source == ScaleOptions::Source::kFirstStep) {
    length = sc.first_step_m;
    metric_ = true;
  } else if (sc.source == ScaleOptions::Source::kSpeed) {
    length = sc.speed_mps * dt_s;
    metric_ = true;
  }
  return length;
}

void Pipeline::Initialise(const FrontEndStep& front,
                          const std::vector<PlaneObservation>& observations, double dt_s,
                          PipelineStep* step) {
  const bool has_motion = front.infinity.ok() && front.infinity->has_motion;
  if (!has_motion) {
    step->note = "waiting to initialise: no reliable motion between the anchors";
    return;
  }
  if (static_cast<int>(step->extracted.size()) < options_.min_planes_to_initialise &&
      !options_.motion_only_steps) {
    step->note = "waiting to initialise: no plane extracted";
    return;
  }
  Rigid3d prev_from_cur = front.infinity->later_from_earlier.Inverse();
  prev_from_cur.translation = prev_from_cur.translation.normalized() * InitialStepLength(dt_s);
  Status s = ekf_.Initialize(prev_from_cur, dt_s);
  if (s.ok()) s = ekf_.Update(observations, &step->ekf);
  if (!s.ok()) {
    step->note = "initialisation failed: " + s.ToString();
    ekf_ = PlaneEkf(intrinsics_, options_.ekf);
    return;
  }
  const AnchorPair& pair = front.pair;
  if (trajectory_.empty() || trajectory_.back().index != pair.earlier_index) {
    if (trajectory_.empty()) world_from_cam_ = Rigid3d();
    trajectory_.push_back({pair.earlier_index, pair.earlier_timestamp_s, world_from_cam_});
  }
  world_from_cam_ = world_from_cam_ * ekf_.prev_from_cur();
  step->tracking = true;
  step->motion_only_start = ekf_.planes().empty();
}

void Pipeline::Advance(const FrontEndStep& front, const std::vector<PlaneObservation>& observations,
                       double dt_s, PipelineStep* step) {
  Status s = ekf_.Predict(dt_s);
  if (s.ok()) s = ekf_.Update(observations, &step->ekf);
  // No tracked plane observed: the pair's own motion, where it has one.
  if (s.ok() && step->ekf.skipped && options_.motion_only_steps && front.infinity.ok() &&
      front.infinity->has_motion) {
    s = ekf_.UpdateMotion(front.infinity->later_from_earlier.Inverse(), &step->ekf);
  }
  if (s.ok() && options_.road_from_frames) s = UpdateRoadFromFrames(front, &step->ekf);
  if (!s.ok()) {
    // Numerical failure: restart the filter on a later pair; the trajectory
    // continues from the last pose at the last step's speed (InitialStepLength).
    step->note = "filter reset: " + s.ToString();
    ResetFilter();
    return;
  }
  world_from_cam_ = world_from_cam_ * ekf_.prev_from_cur();
  step->tracking = true;
}

Status Pipeline::UpdateRoadFromFrames(const FrontEndStep& front, UpdateReport* report) {
  const AnchorPair& pair = front.pair;
  const double dt_s = pair.later_timestamp_s - pair.earlier_timestamp_s;
  // The road's fit rests on the step's rotation and direction of travel: on
  // a step without a motion measurement they are the motion model's guess,
  // and on a 320x240 highway drive the fitted step length followed its drift
  // (36 % short after 2 s; ATE 0.45 -> 1.84 %).
  const bool has_motion = front.infinity.ok() && front.infinity->has_motion;
  // Only where the road was not observed: coasting, or not in the filter.
  const bool road_kept = ekf_.RoadInEarlierCamera().has_value();
  if ((road_kept && !report->road_coasting) || pair.n_b <= 0 || !(dt_s > 0) || !has_motion) {
    return Status::Ok();
  }
  std::vector<InterFrameVector> vectors;
  for (const FrameRecord& frame : frame_poser_.buffered()) {
    if (frame.index <= pair.earlier_index || frame.index >= pair.later_index) continue;
    const double fraction = (frame.timestamp_s - pair.earlier_timestamp_s) / dt_s;
    if (frame.type != PictureType::kB || frame.corrupt || !frame.reference_certain ||
        frame.prev_anchor_index != pair.earlier_index || !(fraction > 0.0) ||
        fraction > kRoadFromFramesMaxFraction) {
      continue;
    }
    for (const MotionVector& mv : frame.mvs) {
      if (mv.direction != RefDirection::kPast) continue;
      const Eigen::Vector2d x(mv.x_px, mv.y_px);
      vectors.push_back({x, x + Eigen::Vector2d(mv.dx_px, mv.dy_px), fraction});
    }
  }
  const Rigid3d step = ekf_.prev_from_cur();
  if (vectors.empty() || !(step.translation.norm() > 0)) return Status::Ok();
  StatusOr<RoadStepReport> road = EstimateRoadStep(
      vectors, intrinsics_, step.R(), step.translation.normalized(), options_.road_step);
  if (!road.ok()) return road.status();
  if (!road->success) return Status::Ok();
  if (!road_kept) {
    roads_from_frames_ += ekf_.AddRoadFromStep(road->q, road->q_cov,
                                               kRoadFromFramesTrackId + roads_from_frames_, report);
    return Status::Ok();
  }
  // The filter takes q's length: its variance is q_cov along q.
  const Eigen::Vector3d along = road->q.normalized();
  return ekf_.UpdateRoadStep(road->q, along.dot(road->q_cov * along), report);
}

void Pipeline::RecordPlanes(const PipelineStep& step, const AnchorPair& pair) {
  for (const PlaneTrack& track : ekf_.planes()) {
    if (track.coasting()) continue;  // not observed in this update
    MapPlane& mp = plane_map_[track.track_id];
    if (mp.track_id < 0) {
      mp.track_id = track.track_id;
      mp.first_seen_index = step.later_index;
      mp.first_seen_s = step.timestamp_s;
    }
    const Plane3d plane_world =
        TransformPlane(world_from_cam_, Plane3d::FromInverseDepth(track.pi));
    mp.normal_world = plane_world.normal;
    mp.distance_m = plane_world.distance;
    mp.pi_cam = track.pi;
    mp.last_seen_index = step.later_index;
    mp.last_seen_s = step.timestamp_s;
    mp.observations = track.observations;
    mp.seen_indices.push_back(step.later_index);
    for (size_t k = 0; k < step.extracted.size(); ++k) {
      if (step.extracted_filter_ids[k] != track.track_id) continue;
      const ExtractedPlane& ex = step.extracted[k];
      mp.mb_indices = ex.mb_indices;
      for (int i : ex.correspondence_indices) {
        if (mp.support_world.size() >= kMaxSupportPointsPerPlane) break;
        const Eigen::Vector3d ray = intrinsics_.Unproject(pair.correspondences[i].x_later_px);
        const double inv_depth = track.pi.dot(ray);
        if (inv_depth <= 0) continue;
        mp.support_world.push_back(world_from_cam_ * (ray / inv_depth));
      }
    }
  }
}

void Pipeline::MaybeFixScaleFromRoad(PipelineStep* step) {
  const ScaleOptions& sc = options_.scale;
  for (const PlaneTrack& track : ekf_.planes()) {
    // A coasting road's pi was observed at an older scale and only predicted
    // since: its height would carry the drift of the coasting stretch.
    if (track.observations < sc.road_min_observations || track.coasting()) continue;
    // Road: pi ~ (0, 1/h, 0), so the camera height h is 1 / |pi|.
    if (!IsRoadLike(track.pi, CameraDown(), sc.road_max_angle_deg)) continue;
    FixScaleFromHeight(sc.camera_height_m * track.pi.norm());
    NoteHeightFix(track.pi, "camera height over the filter's road plane", step);
    return;
  }
}

void Pipeline::FixScaleFromHeight(double s) {
  ApplyScale(s);
  refiner_.SetRoadHeight(options_.scale.camera_height_m);
  metric_ = true;
}

void Pipeline::ApplyScale(double s) {
  ekf_.Rescale(s);
  refiner_.Rescale(s);
  for (TimedPose& p : trajectory_) p.world_from_cam.translation *= s;
  for (FramePose& p : poses_) {
    p.pose.world_from_cam.translation *= s;
    p.quality.position_sigma *= s;
  }
  world_from_cam_.translation *= s;
  for (auto& [id, mp] : plane_map_) {
    mp.distance_m *= s;
    mp.pi_cam /= s;
    for (Eigen::Vector3d& x : mp.support_world) x *= s;
  }
}

PoseQuality Pipeline::AnchorQuality(const PipelineStep& step) const {
  PoseQuality q;
  // PipelineOptions::road_from_frames measured the step's length.
  const bool road = step.ekf.road_step_updated;
  const std::string road_source =
      "the road in the B frames next to the earlier anchor (road_from_frames)";
  q.kind = step.ekf.skipped ? PoseKind::kCoasting : PoseKind::kAnchor;
  if (step.ekf.skipped) {
    q.note = "no tracked plane observed: the motion model's prediction";
    if (road) q.note += ", its step length corrected by " + road_source;
  } else if (road) {
    q.note = "step length also from " + road_source;
  }
  if (step.motion_only()) {
    q.kind = PoseKind::kMotionOnly;
    q.note =
        "no tracked plane observed: rotation and direction of travel from the pair's motion, "
        "step length from " +
        (road ? road_source : std::string("the motion model"));
  }
  // The step translation's covariance (error state [dtheta, dt, ...]).
  const Eigen::MatrixXd& P = ekf_.covariance();
  q.position_sigma = P.rows() >= 6 ? std::sqrt(std::max(0.0, P.block<3, 3>(3, 3).trace())) : 0.0;
  q.inliers = step.ekf.measurements;
  q.rms_px = step.ekf.rms_residual_px;
  return q;
}

void Pipeline::AddFramePoses(const AnchorPair& pair, PipelineStep* step) {
  // Tracking: trajectory_ ends with the later anchor, after the earlier one.
  const TimedPose& later = trajectory_.back();
  const TimedPose& earlier = trajectory_[trajectory_.size() - 2];
  const int64_t last_posed = poses_.empty() ? -1 : poses_.back().pose.index;
  if (last_posed != earlier.index) {  // the trajectory (re)starts on the earlier anchor
    FramePose start;
    start.pose = earlier;
    start.quality.position_sigma = std::numeric_limits<double>::quiet_NaN();
    if (last_posed >= 0) {
      start.quality.gap_frames = earlier.index - last_posed - 1;
      start.quality.note = "re-initialised after a loss: continues from the last pose";
    } else {
      start.quality.note = "first pose: the world frame";
    }
    step->frame_poses.push_back(start);
  }
  PosedAnchorPair posed;
  posed.pair = &pair;
  posed.earlier = earlier;
  posed.later = later;
  posed.extracted = &step->extracted;
  posed.extracted_filter_ids = &step->extracted_filter_ids;
  posed.planes = &step->planes;
  for (FramePose& fp : frame_poser_.PoseBetween(posed)) step->frame_poses.push_back(std::move(fp));
  FramePose anchor;
  anchor.pose = later;
  anchor.quality = AnchorQuality(*step);
  scale_support_.Count(anchor.quality.kind, step->ekf.road_step_updated);
  step->frame_poses.push_back(anchor);
  poses_.insert(poses_.end(), step->frame_poses.begin(), step->frame_poses.end());
}

// The hook of core/refine (docs/METHOD.md "Windowed refinement"). The
// refiner's plane ids are the filter's track ids (extracted_filter_ids), its
// initial planes the filter's, its initial pose for the new anchor the
// refined previous pose composed with the filter's step.
void Pipeline::RefineWindow(const AnchorPair& pair, PipelineStep* step) {
  if (refiner_.size() == 0) {  // (re)start: the earlier anchor's pose is the last in the trajectory
    refiner_.Push(pair.earlier_index, pair.earlier_timestamp_s, trajectory_.back().world_from_cam,
                  {}, {}, -1);
  }
  std::vector<WindowPlaneObservation> observations;
  for (size_t k = 0; k < step->extracted.size(); ++k) {
    WindowPlaneObservation o;
    o.plane_id = step->extracted_filter_ids[k];
    for (int i : step->extracted[k].correspondence_indices) {
      const Correspondence& c = pair.correspondences[i];
      o.x_later_px.push_back(c.x_later_px);
      o.x_earlier_px.push_back(c.x_earlier_px);
      o.variance_px2.push_back(c.variance_px2);
    }
    observations.push_back(std::move(o));
  }
  std::map<int, Eigen::Vector3d> guesses;
  int road_id = -1;
  for (const PlaneTrack& track : ekf_.planes()) {
    guesses[track.track_id] = track.pi;
    if (track.road) road_id = track.track_id;
  }
  // The new anchor's guess: the window's newest pose and the filter's step.
  const Rigid3d guess = refiner_.world_from_cam(refiner_.size() - 1) * ekf_.prev_from_cur();
  refiner_.Push(pair.later_index, pair.later_timestamp_s, guess, std::move(observations), guesses,
                road_id);
  const Status s = refiner_.Refine(&step->refine);
  if (!s.ok()) {  // the filter's pose stands; the window restarts from it
    step->note = s.ToString();
    refiner_.Reset();
    return;
  }
  if (step->refine.rejected) {  // the window does not fit its vectors: restart it
    refiner_.Reset();
    return;
  }
  if (!step->refine.solved) return;
  // The emitted pose: the last emitted pose composed with the window's newest
  // step. Poses already emitted are not revised (final once a step emitted
  // them: the update stream's clients and `slapse run`'s files hold the same
  // poses), and taking the window's newest pose itself would put the
  // revision of the previous anchor into this step's length.
  const size_t n = refiner_.size();
  const Rigid3d step_refined =
      refiner_.world_from_cam(n - 2).Inverse() * refiner_.world_from_cam(n - 1);
  world_from_cam_ = trajectory_.back().world_from_cam * step_refined;
  const double ekf_length = ekf_.prev_from_cur().translation.norm();
  const double refined_length = step_refined.translation.norm();
  if (ekf_length > 0 && refined_length > 0) ekf_.Rescale(refined_length / ekf_length);
}

void Pipeline::MaybeFixScaleFromWindowRoad(PipelineStep* step) {
  const ScaleOptions& sc = options_.scale;
  const WindowRefineReport& r = step->refine;
  if (!(r.solved && r.road_in_window && r.road_pairs >= sc.road_min_window_pairs &&
        r.road_distance > 0)) {
    if (MaybeFixScaleFromMeasuredRoad(step)) return;
    step->scale_note = "metric scale not observable yet: the road plane is seen in " +
                       std::to_string(r.road_pairs) + " of " + std::to_string(r.anchors - 1) +
                       " window pairs (needs " + std::to_string(sc.road_min_window_pairs) +
                       ") and measured on " + std::to_string(road_measured_steps_) +
                       " steps in a row";
    return;
  }
  FixScaleFromHeight(sc.camera_height_m / r.road_distance);
  const std::optional<Eigen::Vector3d> road = refiner_.RoadInNewest();
  NoteHeightFix(
      road.value_or(Eigen::Vector3d::Zero()),
      "camera height over the road seen in " + std::to_string(r.road_pairs) + " window pairs",
      step);
}

bool Pipeline::MaybeFixScaleFromMeasuredRoad(PipelineStep* step) {
  const ScaleOptions& sc = options_.scale;
  const PlaneTrack* road = nullptr;
  for (const PlaneTrack& track : ekf_.planes()) {
    if (track.road) road = &track;
  }
  // Measured on this step: observed by the pair's update, or its step length
  // measured in the B frames (UpdateRoadFromFrames).
  const UpdateReport& u = step->ekf;
  const bool measured = road != nullptr && (u.road_step_updated || u.road_added_from_frames ||
                                            (u.planes_updated > 0 && road->missed_updates == 0));
  road_measured_steps_ = measured ? road_measured_steps_ + 1 : 0;
  if (!measured || road_measured_steps_ < sc.road_min_window_pairs ||
      road->observations < sc.road_min_observations ||
      !IsRoadLike(road->pi, CameraDown(), sc.road_max_angle_deg)) {
    return false;
  }
  // Road: pi ~ (0, 1/h, 0) at the trajectory's scale, so the camera height h
  // is 1 / |pi|.
  FixScaleFromHeight(sc.camera_height_m * road->pi.norm());
  NoteHeightFix(road->pi,
                "camera height over the filter's road, measured on " +
                    std::to_string(road_measured_steps_) + " steps in a row",
                step);
  return true;
}

void Pipeline::NoteHeightFix(const Eigen::Vector3d& road_pi_cam, const std::string& how,
                             PipelineStep* step) {
  const double steepest_deg = SteepestRoadDepressionDeg(road_pi_cam, intrinsics_);
  height_road_depression_deg_ = steepest_deg;
  char seen[160];
  std::snprintf(seen, sizeof seen, "; the image sees the road at most %.1f deg below its horizon",
                steepest_deg);
  step->scale_note = "metric: " + how + seen;
  if (ScaleOptions::HeightScaleWeak(steepest_deg)) {
    char weak[256];
    std::snprintf(weak, sizeof weak,
                  " -- weak: below %.0f deg (a short vertical field of view, or the camera "
                  "pitched up) the height does not place the scale reliably: "
                  "expect errors of several %% or more (docs/TRAJECTORY.md \"Session 28\")",
                  ScaleOptions::kMinRoadDepressionDeg);
    step->scale_note += weak;
  }
}

Status Pipeline::RevisePose(size_t n, const Rigid3d& world_from_cam) {
  const size_t posed = poses_forgotten_ + poses_.size();
  if (n >= posed) {
    return OutOfRangeError("pose " + std::to_string(n) + " of " + std::to_string(posed));
  }
  if (n < first_revisable_pose_) {
    return FailedPreconditionError("pose " + std::to_string(n) + " is final (first revisable: " +
                                   std::to_string(first_revisable_pose_) + ")");
  }
  FramePose& p = poses_[n - poses_forgotten_];  // revisable poses are never forgotten
  p.pose.world_from_cam = world_from_cam;
  ++p.revision;
  auto anchor = std::lower_bound(trajectory_.begin(), trajectory_.end(), p.pose.index,
                                 [](const TimedPose& t, int64_t index) { return t.index < index; });
  if (anchor != trajectory_.end() && anchor->index == p.pose.index) {
    anchor->world_from_cam = world_from_cam;
    // The next step continues from the latest anchor.
    if (anchor + 1 == trajectory_.end()) world_from_cam_ = world_from_cam;
  }
  return Status::Ok();
}

bool Pipeline::IsFinite(const Rigid3d& pose) {
  return pose.translation.allFinite() && pose.rotation.coeffs().allFinite();
}

void Pipeline::RestartOnNonFinite(const Rigid3d& world_from_cam_before, PipelineStep* step) {
  world_from_cam_ = world_from_cam_before;
  step->tracking = false;
  step->extracted_filter_ids.clear();
  step->note = "filter reset: the motion estimate was not finite";
  ResetFilter();
}

bool Pipeline::ScaleMayChange() const {
  return options_.scale.source == ScaleOptions::Source::kCameraHeight && !metric_ &&
         !scale_given_up_;
}

void Pipeline::ForgetFinal(size_t keep_final_poses) {
  if (ScaleMayChange()) return;
  // Final poses are those before first_revisable_pose_; drop in chunks (of
  // at least as many as are kept, plus 16) so that the erase is amortised.
  const size_t final_kept = first_revisable_pose_ - poses_forgotten_;
  if (final_kept <= 2 * keep_final_poses + 16) return;
  const size_t drop = final_kept - keep_final_poses;
  poses_.erase(poses_.begin(), poses_.begin() + static_cast<std::ptrdiff_t>(drop));
  poses_forgotten_ += drop;
  // The anchors before the first pose kept, but the last two (the next step
  // continues from them).
  const int64_t first_kept_index = poses_.front().pose.index;
  size_t anchors = 0;
  while (anchors + 2 < trajectory_.size() && trajectory_[anchors].index < first_kept_index) {
    ++anchors;
  }
  trajectory_.erase(trajectory_.begin(),
                    trajectory_.begin() + static_cast<std::ptrdiff_t>(anchors));
  anchors_forgotten_ += anchors;
  // Planes the filter no longer holds (their ids are never reused) and that
  // were last seen before the first anchor kept.
  std::set<int> held;
  for (const PlaneTrack& t : ekf_.planes()) held.insert(t.track_id);
  for (auto it = plane_map_.begin(); it != plane_map_.end();) {
    if (!held.count(it->first) && it->second.last_seen_index < trajectory_.front().index) {
      it = plane_map_.erase(it);
      ++planes_forgotten_;
    } else {
      ++it;
    }
  }
}

}  // namespace slapse
