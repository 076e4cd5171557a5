#include "core/refine/window_refiner.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <set>
#include <utility>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include "core/common/angles.h"
#include "core/common/so3.h"
#include "core/refine/block_lm.h"
#include "core/refine/plane_transfer_cost.h"

namespace slapse {
namespace {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;

// The plane-induced transfer of one plane's macroblocks in one pair is
// core/refine/plane_transfer_cost.h (PlaneTransferCost), one cost block per
// (pair, plane) so that the pose and plane algebra is done once for all its
// macroblocks. The macroblock weights s_j there are 1 / sigma_j times the
// Huber weight sqrt(min(1, k / |r_j|)) of the macroblock's normalised
// residual at the start of the solve (one IRLS step per solve; the window is
// solved again at every anchor, so the weights follow).

// Motion prior over three consecutive anchors a, b, c (gauge (d)):
//   v_1 = R_a^T (c_b - c_a) / dt_1,  v_2 = R_b^T (c_c - c_b) / dt_2   (body frame)
//   w_1 = Log(R_a^T R_b) / dt_1,     w_2 = Log(R_b^T R_c) / dt_2
//   r = [(v_2 - v_1) / s_v; (w_2 - w_1) / s_w]
// with s_v = q_v |v_1| sqrt(dt), s_w = q_w sqrt(dt), dt = (dt_1 + dt_2) / 2:
// a random walk of the velocities, like the EKF's process noise.
struct MotionPriorResidual {
  MotionPriorResidual(double dt1, double dt2, double sigma_v, double sigma_w)
      : dt1(dt1), dt2(dt2), inv_sv(1.0 / sigma_v), inv_sw(1.0 / sigma_w) {}

  template <typename T>
  static Vec3<T> RelativeRotationLog(const Eigen::Quaternion<T>& a, const Eigen::Quaternion<T>& b) {
    const Eigen::Quaternion<T> q = a.conjugate() * b;
    const T wxyz[4] = {q.w(), q.x(), q.y(), q.z()};
    Vec3<T> aa;
    ceres::QuaternionToAngleAxis(wxyz, aa.data());
    return aa;
  }

  template <typename T>
  bool operator()(const T* q_a, const T* c_a, const T* q_b, const T* c_b, const T* q_c,
                  const T* c_c, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> qa(q_a), qb(q_b), qc(q_c);
    const Eigen::Map<const Vec3<T>> ca(c_a), cb(c_b), cc(c_c);
    const Vec3<T> v1 = qa.conjugate() * (cb - ca) / T(dt1);
    const Vec3<T> v2 = qb.conjugate() * (cc - cb) / T(dt2);
    const Vec3<T> w1 = RelativeRotationLog<T>(qa, qb) / T(dt1);
    const Vec3<T> w2 = RelativeRotationLog<T>(qb, qc) / T(dt2);
    for (int i = 0; i < 3; ++i) {
      residual[i] = (v2(i) - v1(i)) * T(inv_sv);
      residual[3 + i] = (w2(i) - w1(i)) * T(inv_sw);
    }
    return true;
  }

  double dt1, dt2, inv_sv, inv_sw;
};

// Gauge (a): the oldest step's length, r = (|c_1 - c_0| - L) / (rel L), c_0 constant.
struct StepLengthResidual {
  StepLengthResidual(const Eigen::Vector3d& c0, double length, double rel_sigma)
      : c0(c0), length(length), inv_sigma(1.0 / (rel_sigma * length)) {}
  template <typename T>
  bool operator()(const T* c_1, T* residual) const {
    const Eigen::Map<const Vec3<T>> c1(c_1);
    residual[0] = ((c1 - c0.cast<T>()).norm() - T(length)) * T(inv_sigma);
    return true;
  }
  Eigen::Vector3d c0;
  double length, inv_sigma;
};

// Gauge (c): the road's distance from the oldest camera, 1 / |pi_r|.
struct RoadHeightResidual {
  RoadHeightResidual(double height, double rel_sigma)
      : height(height), inv_sigma(1.0 / (rel_sigma * height)) {}
  template <typename T>
  bool operator()(const T* pi_r, T* residual) const {
    const Eigen::Map<const Vec3<T>> pi(pi_r);
    residual[0] = (T(1.0) / pi.norm() - T(height)) * T(inv_sigma);
    return true;
  }
  double height, inv_sigma;
};

// Gauge (e): the road's attitude in camera i. With R_i the rotation of
// world_from_cam_i, R_wr that of the oldest camera (constant) and pi_r the
// road in the oldest camera, the road's unit normal in camera i is
//   n_i = R_i^T R_wr pi_r / |pi_r|,
// and r = B^T (n_i - n_ref) / sigma, B = TangentBasis(n_ref) (two angles, rad,
// for small deviations).
struct RoadAttitudeResidual {
  RoadAttitudeResidual(const Eigen::Matrix3d& R_wr, const Eigen::Vector3d& n_ref, double sigma_rad)
      : R_wr(R_wr), n_ref(n_ref), B(TangentBasis(n_ref)), inv_sigma(1.0 / sigma_rad) {}
  template <typename T>
  bool operator()(const T* q_i, const T* pi_r, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_i);
    const Eigen::Map<const Vec3<T>> pi(pi_r);
    const Vec3<T> n_i = q.conjugate() * (R_wr.cast<T>() * (pi / pi.norm()));
    const Eigen::Matrix<T, 2, 1> e = B.transpose().cast<T>() * (n_i - n_ref.cast<T>());
    residual[0] = e(0) * T(inv_sigma);
    residual[1] = e(1) * T(inv_sigma);
    return true;
  }
  Eigen::Matrix3d R_wr;
  Eigen::Vector3d n_ref;
  Eigen::Matrix<double, 3, 2> B;
  double inv_sigma;
};

// Gauge (f): camera i's centre c_i (world) lies in the plane through the
// oldest camera parallel to the road,
//   h_i = pi_r^T R_wr^T (c_i - c_wr) = 0
// (its height change relative to the road's distance; pi_r the road in the
// oldest camera, (R_wr, c_wr) that camera's world_from_cam, constant during
// a solve), r = h_i / sigma.
struct RoadLevelResidual {
  RoadLevelResidual(const Eigen::Matrix3d& R_wr, const Eigen::Vector3d& c_wr, double sigma)
      : R_rw(R_wr.transpose()), c_wr(c_wr), inv_sigma(1.0 / sigma) {}
  template <typename T>
  bool operator()(const T* c_i, const T* pi_r, T* residual) const {
    const Eigen::Map<const Vec3<T>> c(c_i);
    const Eigen::Map<const Vec3<T>> pi(pi_r);
    residual[0] = pi.dot(R_rw.cast<T>() * (c - c_wr.cast<T>())) * T(inv_sigma);
    return true;
  }
  Eigen::Matrix3d R_rw;
  Eigen::Vector3d c_wr;
  double inv_sigma;
};

// Poses as parameter blocks: Eigen quaternion (x, y, z, w) and centre.
struct PoseBlock {
  Eigen::Quaterniond q;
  Eigen::Vector3d c;
};

}  // namespace

Status WindowRefinerOptions::Check(const std::string& who) const {
  if (window_anchors < 3 || max_iterations < 1 || max_mbs_per_plane < 4 || !(extra_sigma_px > 0) ||
      !(huber_k > 0) || !(gauge_step_rel_sigma > 0) || !(metric_gauge_step_rel_sigma > 0) ||
      !(road_height_rel_sigma > 0) || !(speed_change_rel_per_sqrt_s > 0) ||
      !(angular_rate_change_rad_s_per_sqrt_s > 0) || !(road_attitude_sigma_deg >= 0) ||
      !(road_level_rel_sigma >= 0) || road_reference_solves < 1 ||
      !(reassociate_max_angle_deg > 0) || !(reassociate_max_distance_ratio > 1) ||
      !(max_final_rms > 0)) {
    return InvalidArgumentError(who +
                                ": window_anchors must be >= 3, max_iterations >= 1, "
                                "max_mbs_per_plane >= 4, road_reference_solves >= 1, every sigma "
                                "> 0 (road_attitude_sigma_deg, road_level_rel_sigma >= 0), "
                                "reassociate_max_angle_deg "
                                "and max_final_rms > 0, reassociate_max_distance_ratio > 1");
  }
  return Status::Ok();
}

WindowRefiner::WindowRefiner(const Intrinsics& intrinsics, WindowRefinerOptions options)
    : intrinsics_(intrinsics), options_(options) {}

void WindowRefiner::Reset() {
  anchors_.clear();
  planes_world_.clear();
  plane_solves_.clear();
  road_id_ = -1;
  next_internal_id_ = -2;
  before_.reset();
}

// A plane id whose new guess (the filter's plane) is a different surface from
// the window's plane (the filter restarts a track that fails its association
// gate under the same id): the window's plane and its older observations move
// to a fresh internal id, and the id starts anew from the guess. Compared in
// the newest camera, the normals' angle and the distances' ratio (the filter
// is rescaled to the window at every step, so their scales agree).
void WindowRefiner::Reassociate(int plane_id, const Eigen::Vector3d& guess_cam,
                                const Rigid3d& world_from_cam) {
  const auto it = planes_world_.find(plane_id);
  if (it == planes_world_.end() || !(guess_cam.norm() > 0)) return;
  const Plane3d old_cam = PlaneInCamera(world_from_cam, it->second, true);
  const Plane3d new_cam = Plane3d::FromInverseDepth(guess_cam);
  const double cos_angle = std::clamp(old_cam.normal.dot(new_cam.normal), -1.0, 1.0);
  const double ratio = old_cam.distance > 0 ? new_cam.distance / old_cam.distance : 0.0;
  if (std::acos(cos_angle) <= DegToRad(options_.reassociate_max_angle_deg) && ratio > 0 &&
      std::abs(std::log(ratio)) <= std::log(options_.reassociate_max_distance_ratio)) {
    return;
  }
  const int moved = next_internal_id_--;
  planes_world_[moved] = it->second;
  planes_world_.erase(it);
  if (plane_solves_.count(plane_id)) {
    plane_solves_[moved] = plane_solves_[plane_id];
    plane_solves_.erase(plane_id);
  }
  for (Anchor& a : anchors_) {
    for (WindowPlaneObservation& old : a.observations) {
      if (old.plane_id == plane_id) old.plane_id = moved;
    }
  }
  if (road_id_ == plane_id) road_id_ = moved;
}

void WindowRefiner::Push(int64_t index, double timestamp_s, const Rigid3d& world_from_cam,
                         std::vector<WindowPlaneObservation> observations,
                         const std::map<int, Eigen::Vector3d>& plane_guess_cam, int road_id) {
  Anchor a;
  a.index = index;
  a.timestamp_s = timestamp_s;
  a.world_from_cam = world_from_cam;
  // Observations of planes the window neither holds nor gets a guess for are skipped.
  for (WindowPlaneObservation& o : observations) {
    const auto guess = plane_guess_cam.find(o.plane_id);
    if (guess != plane_guess_cam.end()) Reassociate(o.plane_id, guess->second, world_from_cam);
    if (planes_world_.count(o.plane_id) == 0) {
      if (guess == plane_guess_cam.end() || !(guess->second.norm() > 0)) continue;
      planes_world_[o.plane_id] =
          TransformPlane(world_from_cam, Plane3d::FromInverseDepth(guess->second));
    }
    if (!anchors_.empty()) a.observations.push_back(std::move(o));
  }
  if (road_id >= 0) road_id_ = road_id;
  anchors_.push_back(std::move(a));
  while (static_cast<int>(anchors_.size()) > options_.window_anchors) DropOldest();
}

void WindowRefiner::DropOldest() {
  Anchor oldest = std::move(anchors_.front());
  anchors_.pop_front();
  oldest.observations.clear();
  before_ = std::move(oldest);
  // Planes no pair in the window sees any more leave it.
  std::set<int> seen;
  for (size_t k = 1; k < anchors_.size(); ++k) {
    for (const WindowPlaneObservation& o : anchors_[k].observations) seen.insert(o.plane_id);
  }
  for (auto it = planes_world_.begin(); it != planes_world_.end();) {
    if (seen.count(it->first)) {
      ++it;
    } else {
      plane_solves_.erase(it->first);
      it = planes_world_.erase(it);
    }
  }
}

// The window's parameter blocks and the problem over them.
struct WindowRefiner::Problem {
  std::vector<PoseBlock> poses;        // [before (if any),] anchors oldest .. newest
  std::map<int, Eigen::Vector3d> pis;  // plane id -> pi in the oldest camera
  BlockLmProblem problem;
  int residuals = 0;
  Status status;  // the first error in building the problem

  void Note(const Status& s) {
    if (status.ok() && !s.ok()) status = s;
  }
  void AddPose(PoseBlock* p, bool constant) {
    Note(problem.AddQuaternionBlock(p->q.coeffs().data()));
    Note(problem.AddVectorBlock(p->c.data(), 3));
    if (constant) {
      Note(problem.SetConstant(p->q.coeffs().data()));
      Note(problem.SetConstant(p->c.data()));
    }
  }
  void Add(ceres::CostFunction* cost, const std::vector<double*>& blocks) {
    Note(problem.AddResidualBlock(std::unique_ptr<ceres::CostFunction>(cost), blocks));
  }
};

Status WindowRefiner::Refine(WindowRefineReport* report) {
  WindowRefineReport local;
  WindowRefineReport& rep = report != nullptr ? *report : local;
  rep = WindowRefineReport();
  const size_t n = anchors_.size();
  rep.anchors = static_cast<int>(n);
  if (n < 2) return Status::Ok();
  Problem wp;
  const size_t first = before_ ? 1 : 0;  // index of anchor 0 in wp.poses
  wp.poses.reserve(n + 1);
  if (before_)
    wp.poses.push_back({before_->world_from_cam.rotation, before_->world_from_cam.translation});
  for (const Anchor& a : anchors_)
    wp.poses.push_back({a.world_from_cam.rotation, a.world_from_cam.translation});
  for (size_t k = 0; k < wp.poses.size(); ++k) wp.AddPose(&wp.poses[k], k <= first);
  const Rigid3d world_from_r = anchors_[0].world_from_cam;
  for (const auto& [id, plane] : planes_world_) {
    const Plane3d p = PlaneInCamera(world_from_r, plane, true);
    if (p.distance > 0) wp.pis[id] = p.InverseDepth();
  }
  for (auto& [id, pi] : wp.pis) wp.Note(wp.problem.AddVectorBlock(pi.data(), 3));
  const double before_step =
      (anchors_[n - 1].world_from_cam.translation - anchors_[n - 2].world_from_cam.translation)
          .norm();
  AddTransferResiduals(&wp, first, &rep);
  if (wp.residuals == 0) return Status::Ok();
  AddGaugeAndPriors(&wp, first, &rep);

  if (!wp.status.ok()) return wp.status;

  BlockLmOptions lm;
  lm.max_iterations = options_.max_iterations;
  BlockLmSummary summary;
  if (Status s = wp.problem.Solve(lm, &summary); !s.ok()) {
    return InternalError("window refinement failed: " + s.message());
  }
  rep.residuals = wp.residuals;
  rep.initial_rms = std::sqrt(2.0 * summary.initial_cost / wp.residuals);
  rep.final_rms = std::sqrt(2.0 * summary.final_cost / wp.residuals);
  if (rep.final_rms > options_.max_final_rms) {
    rep.rejected = true;
    return Status::Ok();
  }
  rep.solved = true;
  for (size_t k = 1; k < n; ++k) {
    anchors_[k].world_from_cam = Rigid3d(wp.poses[first + k].q, wp.poses[first + k].c);
  }
  for (const auto& [id, pi] : wp.pis) {
    planes_world_[id] = TransformPlane(world_from_r, Plane3d::FromInverseDepth(pi));
    ++plane_solves_[id];
  }
  rep.planes = static_cast<int>(wp.pis.size());
  const double after_step =
      (anchors_[n - 1].world_from_cam.translation - anchors_[n - 2].world_from_cam.translation)
          .norm();
  rep.newest_step_ratio = before_step > 0 ? after_step / before_step : 1.0;
  if (const auto road = RoadInNewest(); road.has_value()) {
    rep.road_in_window = true;
    rep.road_distance = 1.0 / road->norm();
  }
  AccumulateRoadReferences(wp, rep);
  return Status::Ok();
}

// (c) and (e)'s references: the mean of the refined road (unit normal, and
// distance from the oldest camera) over the first road_reference_solves
// solves of a full window in which at least half the pairs saw the road;
// those solves run without (e), with (c) at the previous estimate. Held from
// then on: averaging later solves, which the prior pulls to the reference,
// would only confirm it.
void WindowRefiner::AccumulateRoadReferences(const Problem& wp, const WindowRefineReport& rep) {
  if (!(options_.road_attitude_sigma_deg > 0) || road_normal_cam_) return;
  const int pairs = options_.window_anchors - 1;
  if (static_cast<int>(anchors_.size()) < options_.window_anchors || 2 * rep.road_pairs < pairs) {
    return;
  }
  const auto road = wp.pis.find(road_id_);
  if (road == wp.pis.end() || !(road->second.norm() > 0)) return;
  road_normal_sum_ += road->second.normalized();
  road_height_sum_ += 1.0 / road->second.norm();
  if (++road_reference_solves_ < options_.road_reference_solves) return;
  road_normal_cam_ = road_normal_sum_.normalized();
  if (!road_height_) road_height_ = road_height_sum_ / road_reference_solves_;
}

void WindowRefiner::AddTransferResiduals(Problem* problem, size_t first,
                                         WindowRefineReport* rep) const {
  Problem& wp = *problem;
  const Eigen::Matrix3d K_inv = intrinsics_.K().inverse();
  for (size_t k = 1; k < anchors_.size(); ++k) {
    PoseBlock& a = wp.poses[first + k - 1];
    PoseBlock& b = wp.poses[first + k];
    bool road_seen = false;
    for (const WindowPlaneObservation& o : anchors_[k].observations) {
      auto plane = wp.pis.find(o.plane_id);
      if (plane == wp.pis.end()) continue;
      PlaneTransferData data;
      data.fx = intrinsics_.fx_px;
      data.fy = intrinsics_.fy_px;
      data.cx = intrinsics_.cx_px;
      data.cy = intrinsics_.cy_px;
      data.R_rw = anchors_[0].world_from_cam.R().transpose();
      data.c_wr = anchors_[0].world_from_cam.translation;
      const size_t m = o.x_later_px.size();
      const size_t stride =
          std::max<size_t>(1, (m + options_.max_mbs_per_plane - 1) / options_.max_mbs_per_plane);
      std::vector<PlaneTransferData::Mb> all;
      for (size_t i = 0; i < m; i += stride) {
        const double sigma =
            std::sqrt(o.variance_px2[i] + options_.extra_sigma_px * options_.extra_sigma_px);
        all.push_back({K_inv * o.x_later_px[i].homogeneous(), o.x_earlier_px[i], 1.0 / sigma});
      }
      // Huber weights at the start; macroblocks behind a camera there are dropped.
      const Eigen::Matrix3d H = data.Homography(
          a.q.coeffs().data(), a.c.data(), b.q.coeffs().data(), b.c.data(), plane->second.data());
      for (const PlaneTransferData::Mb& mb : all) {
        double r1[2];
        if (!data.Residual(H, mb, r1)) continue;
        const double norm = std::hypot(r1[0], r1[1]);
        data.mbs.push_back(mb);
        data.mbs.back().scale *= norm > options_.huber_k ? std::sqrt(options_.huber_k / norm) : 1.0;
      }
      if (data.mbs.empty()) continue;
      wp.residuals += static_cast<int>(data.mbs.size());
      wp.Add(
          new PlaneTransferCost(std::move(data)),
          {a.q.coeffs().data(), a.c.data(), b.q.coeffs().data(), b.c.data(), plane->second.data()});
      road_seen = road_seen || o.plane_id == road_id_;
    }
    rep->road_pairs += road_seen ? 1 : 0;
  }
}

void WindowRefiner::AddGaugeAndPriors(Problem* problem, size_t first, WindowRefineReport* rep) {
  Problem& wp = *problem;
  // (a) the oldest step's length.
  const Eigen::Vector3d& c0 = wp.poses[first].c;
  const double length = (wp.poses[first + 1].c - c0).norm();
  if (length > 0) {
    wp.Add(
        new ceres::AutoDiffCostFunction<StepLengthResidual, 1, 3>(new StepLengthResidual(
            c0, length,
            metric_height_ ? options_.metric_gauge_step_rel_sigma : options_.gauge_step_rel_sigma)),
        {wp.poses[first + 1].c.data()});
  }
  // (c) the road's height, once it took part in a solve (or is metric), (f)
  // the cameras' level above it, and
  // (e) its attitude, once the references are taken (AccumulateRoadReferences:
  // only with (e) on; the height held alone made the MPEG-2 tuning drives
  // worse, docs/METHOD.md "The road's attitude").
  const auto road = wp.pis.find(road_id_);
  if (road != wp.pis.end() && rep->road_pairs > 0 &&
      (road_height_.has_value() || plane_solves_.count(road_id_))) {
    wp.Add(new ceres::AutoDiffCostFunction<RoadHeightResidual, 1, 3>(new RoadHeightResidual(
               road_height_.value_or(1.0 / road->second.norm()), options_.road_height_rel_sigma)),
           {road->second.data()});
    if (options_.road_level_rel_sigma > 0) {
      const Rigid3d& world_from_r = anchors_[0].world_from_cam;
      for (size_t k = 1; k < anchors_.size(); ++k) {
        wp.Add(new ceres::AutoDiffCostFunction<RoadLevelResidual, 1, 3, 3>(new RoadLevelResidual(
                   world_from_r.R(), world_from_r.translation,
                   options_.road_level_rel_sigma * std::sqrt(static_cast<double>(k)))),
               {wp.poses[first + k].c.data(), road->second.data()});
      }
    }
    if (road_normal_cam_) {
      const Eigen::Matrix3d R_wr = anchors_[0].world_from_cam.R();
      const double sigma_rad = DegToRad(options_.road_attitude_sigma_deg);
      for (size_t k = first; k < wp.poses.size(); ++k) {
        wp.Add(new ceres::AutoDiffCostFunction<RoadAttitudeResidual, 2, 4, 3>(
                   new RoadAttitudeResidual(R_wr, *road_normal_cam_, sigma_rad)),
               {wp.poses[k].q.coeffs().data(), road->second.data()});
      }
    }
  }
  // (d) the motion prior over each three consecutive poses.
  double max_speed = 0;
  std::vector<double> t_s;
  if (before_) t_s.push_back(before_->timestamp_s);
  for (const Anchor& a : anchors_) t_s.push_back(a.timestamp_s);
  for (size_t k = 1; k < wp.poses.size(); ++k) {
    const double dt = t_s[k] - t_s[k - 1];
    if (dt > 0) max_speed = std::max(max_speed, (wp.poses[k].c - wp.poses[k - 1].c).norm() / dt);
  }
  for (size_t k = 2; k < wp.poses.size(); ++k) {
    const double dt1 = t_s[k - 1] - t_s[k - 2], dt2 = t_s[k] - t_s[k - 1];
    if (!(dt1 > 0 && dt2 > 0)) continue;
    const double speed =
        std::max((wp.poses[k - 1].c - wp.poses[k - 2].c).norm() / dt1, 1e-3 * max_speed);
    if (!(speed > 0)) continue;
    // Random walk of the velocities between the steps' midpoints, dt apart.
    const double sqrt_dt = std::sqrt(0.5 * (dt1 + dt2));
    PoseBlock &a = wp.poses[k - 2], &b = wp.poses[k - 1], &c = wp.poses[k];
    wp.Add(new ceres::AutoDiffCostFunction<MotionPriorResidual, 6, 4, 3, 4, 3, 4, 3>(
               new MotionPriorResidual(dt1, dt2,
                                       options_.speed_change_rel_per_sqrt_s * speed * sqrt_dt,
                                       options_.angular_rate_change_rad_s_per_sqrt_s * sqrt_dt)),
           {a.q.coeffs().data(), a.c.data(), b.q.coeffs().data(), b.c.data(), c.q.coeffs().data(),
            c.c.data()});
  }
}

std::optional<Eigen::Vector3d> WindowRefiner::RoadInNewest() const {
  const auto it = planes_world_.find(road_id_);
  if (it == planes_world_.end() || anchors_.empty()) return std::nullopt;
  const Plane3d p = PlaneInCamera(anchors_.back().world_from_cam, it->second, true);
  if (!(p.distance > 0)) return std::nullopt;
  return p.InverseDepth();
}

void WindowRefiner::Rescale(double s) {
  for (Anchor& a : anchors_) a.world_from_cam.translation *= s;
  if (before_) before_->world_from_cam.translation *= s;
  for (auto& [id, plane] : planes_world_) plane.distance *= s;
  if (road_height_) *road_height_ *= s;
  road_height_sum_ *= s;
}

}  // namespace slapse
