#include "lab/sim/camera_path.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/common/angles.h"
#include "lab/sim/random.h"

namespace slapse {

namespace {

// Radians per degree (angles.h: DegToRad(1) is exactly pi / 180). The path
// and scene multiply by it, which is not DegToRad's x * pi / 180 bit for bit:
// kept so that simulated drives stay identical.
const double kDeg = DegToRad(1.0);

// A sum of sinusoids: sum_k a_k sin(w_k t + phi_k).
struct Sinusoids {
  std::vector<double> amp, omega, phase;
  double operator()(double t) const {
    double v = 0.0;
    for (size_t k = 0; k < amp.size(); ++k) v += amp[k] * std::sin(omega[k] * t + phase[k]);
    return v;
  }
};

// `n` components with periods in [period_min, period_max] s and amplitudes summing to `peak`.
Sinusoids MakeSinusoids(SimRandom& rng, int n, double peak, double period_min, double period_max) {
  Sinusoids s;
  double total = 0.0;
  for (int k = 0; k < n; ++k) {
    s.amp.push_back(rng.Uniform(0.5, 1.0));
    s.omega.push_back(2.0 * M_PI / rng.Uniform(period_min, period_max));
    s.phase.push_back(rng.Uniform(0.0, 2.0 * M_PI));
    total += s.amp.back();
  }
  for (double& a : s.amp) a *= peak / total;
  return s;
}

}  // namespace

Eigen::Matrix3d WorldFromCamRotation(double heading_rad, double pitch_down_rad, double roll_rad) {
  // Level camera: columns are the camera axes in the world: x right, y down, z forward.
  const Eigen::Vector3d forward(std::cos(heading_rad), std::sin(heading_rad), 0.0);
  const Eigen::Vector3d right(std::sin(heading_rad), -std::cos(heading_rad), 0.0);
  Eigen::Matrix3d level;
  level.col(0) = right;
  level.col(1) = -Eigen::Vector3d::UnitZ();
  level.col(2) = forward;
  // A positive rotation about camera x tilts the optical axis up (towards -y).
  const Eigen::Matrix3d pitch =
      Eigen::AngleAxisd(-pitch_down_rad, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d roll =
      Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return level * pitch * roll;
}

double MaxPathLength(const PathOptions& o) {
  // The lane is up to ~25% longer than the centreline on the outside of the
  // tightest bend allowed; be generous.
  return o.start_s_m + 1.3 * o.max_speed_mps * std::max(0, o.num_frames - 1) / o.fps;
}

StatusOr<CameraPath> GenerateCameraPath(const Scene& scene, const PathOptions& o) {
  if (!(o.fps > 0 && o.fps <= 1000) || o.num_frames < 1) {
    return InvalidArgumentError("path needs fps in (0, 1000] and num_frames >= 1");
  }
  if (!(o.min_speed_mps > 0 && o.max_speed_mps >= o.min_speed_mps && o.max_speed_mps < 100)) {
    return InvalidArgumentError("path speeds must satisfy 0 < min <= max < 100 m/s");
  }
  if (!(o.camera_height_min_m > 0 && o.camera_height_max_m >= o.camera_height_min_m) ||
      !(o.pitch_down_max_deg >= o.pitch_down_min_deg) || !(o.vibration_deg >= 0) ||
      !(o.bounce_m >= 0 && o.bounce_m < o.camera_height_min_m) || !(o.heading_smoothing_m > 0)) {
    return InvalidArgumentError(
        "bad camera height / pitch / vibration / bounce / smoothing options");
  }
  const Centreline& cl = scene.centreline;
  if (cl.segments().empty()) return FailedPreconditionError("scene has no centreline");

  SimRandom rng(Mix64(o.seed ^ 0x50415448ULL));
  CameraPath path;
  path.camera_height_m = rng.Uniform(o.camera_height_min_m, o.camera_height_max_m);
  path.pitch_down_deg = rng.Uniform(o.pitch_down_min_deg, o.pitch_down_max_deg);
  // Speed: mid-range plus two slow sinusoids that stay within 90% of the range.
  const double v_mid = 0.5 * (o.min_speed_mps + o.max_speed_mps);
  const double v_half = 0.5 * (o.max_speed_mps - o.min_speed_mps);
  const Sinusoids speed = MakeSinusoids(rng, 2, 0.9 * v_half, 5.0, 16.0);
  const Sinusoids pitch_vib = MakeSinusoids(rng, 3, o.vibration_deg * kDeg, 0.33, 1.25);
  const Sinusoids roll_vib = MakeSinusoids(rng, 3, 0.7 * o.vibration_deg * kDeg, 0.33, 1.25);
  // The bounce draws from its own stream, so the draws above (and every
  // drive's path but its height) do not depend on it.
  SimRandom bounce_rng(Mix64(o.seed ^ 0x424F554E4345ULL));
  const Sinusoids bounce = MakeSinusoids(bounce_rng, 3, o.bounce_m, 0.4, 1.5);
  const double lane = scene.lane_offset_m;

  // ds/dt along the centreline for a car on the lane at lateral offset `lane`:
  // the lane's arc length grows by (1 - curvature * lane) per unit of s.
  auto ds_dt = [&](double t, double s) {
    return (v_mid + speed(t)) / (1.0 - cl.Curvature(s) * lane);
  };
  const double dt = 1.0 / o.fps;
  const int substeps = 16;
  const double h = dt / substeps;
  // `steps` RK4 substeps of ds/dt from (t0, s).
  auto advance = [&](double t0, double s, int steps) {
    for (int k = 0; k < steps; ++k) {
      const double tk = t0 + k * h;
      const double k1 = ds_dt(tk, s);
      const double k2 = ds_dt(tk + 0.5 * h, s + 0.5 * h * k1);
      const double k3 = ds_dt(tk + 0.5 * h, s + 0.5 * h * k2);
      const double k4 = ds_dt(tk + h, s + h * k3);
      s += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
    }
    return s;
  };
  const double w = o.heading_smoothing_m;
  // The camera at time t and arc length s.
  auto pose_at = [&](double t, double s) {
    const Eigen::Vector2d p = cl.Offset(s, lane);
    const Eigen::Vector3d pos(p.x(), p.y(), path.camera_height_m + bounce(t));
    const double heading = (cl.HeadingIntegral(s + w) - cl.HeadingIntegral(s - w)) / (2.0 * w);
    const Eigen::Matrix3d r =
        WorldFromCamRotation(heading, path.pitch_down_deg * kDeg + pitch_vib(t), roll_vib(t));
    return Rigid3d(r, pos);
  };
  double s = o.start_s_m;
  Eigen::Vector3d prev_pos = Eigen::Vector3d::Zero();
  for (int i = 0; i < o.num_frames; ++i) {
    const double t = i * dt;
    if (i > 0) s = advance((i - 1) * dt, s, substeps);
    Rigid3d pose = pose_at(t, s);
    if (scene.road.s_end_m > 0.0 && s > scene.road.s_end_m - 50.0) {
      return OutOfRangeError("the street (" + std::to_string(scene.road.s_end_m) +
                             " m) is too short for the path: frame " + std::to_string(i) +
                             " reaches s = " + std::to_string(s) + " m");
    }
    // Keep consecutive quaternions in the same hemisphere (q and -q are the same rotation).
    if (i > 0 && pose.rotation.dot(path.world_from_cam.back().rotation) < 0) {
      pose.rotation.coeffs() *= -1.0;
    }
    if (o.half_frame_poses) {
      Rigid3d half = pose_at(t + 0.5 * dt, advance(t, s, substeps / 2));
      if (half.rotation.dot(pose.rotation) < 0) half.rotation.coeffs() *= -1.0;
      path.half_frame_world_from_cam.push_back(half);
    }
    path.timestamps_s.push_back(t);
    path.world_from_cam.push_back(pose);
    path.s_m.push_back(s);
    path.speed_mps.push_back(v_mid + speed(t));
    if (i > 0) path.distance_m += (pose.translation - prev_pos).norm();
    prev_pos = pose.translation;
  }
  return path;
}

}  // namespace slapse
