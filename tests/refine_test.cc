// WindowRefiner (core/refine) on synthetic correspondences with exact ground
// truth: a camera driving a straight street with a slight turn, a road plane
// and walls; the pair observations are exact plane-induced transfers (plus
// fixed-seed noise where said).
#include "core/refine/window_refiner.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <vector>

#include "core/common/angles.h"
#include "core/common/plane.h"
#include "core/refine/plane_transfer_cost.h"

namespace slapse {
namespace {

constexpr double kDtS = 0.1;
constexpr double kStepM = 1.2;  // 12 m/s

Intrinsics TestIntrinsics() {
  Intrinsics k;
  k.fx_px = k.fy_px = 457.0;
  k.cx_px = 319.5;
  k.cy_px = 239.5;
  k.width_px = 640;
  k.height_px = 480;
  return k;
}

// Anchor k's true pose: forward along z, yawing 0.5 deg per step.
Rigid3d TruePose(int k) {
  Rigid3d pose;
  double yaw = 0.0;
  for (int i = 0; i < k; ++i) {
    const Eigen::Quaterniond r(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()));
    pose.translation += r * Eigen::Vector3d(0, 0, kStepM);
    yaw += 0.5 * M_PI / 180.0;
  }
  pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()));
  return pose;
}

struct WorldPlane {
  int id;
  Plane3d plane;                      // world frame
  int first, last;                    // anchors (later anchor of a pair) that observe it
  double u_min, u_max, v_min, v_max;  // image region its blocks are sampled from
};

// The street: the road (1.5 m below), a left wall seen throughout, and a
// right-side group that turns over at anchor 8 (walls 2, 3 until 7; walls 4, 5
// from 8 on).
std::vector<WorldPlane> Street(bool with_road) {
  std::vector<WorldPlane> planes;
  if (with_road) planes.push_back({0, {{0, 1, 0}, 1.5}, 1, 100, 40, 600, 330, 470});
  planes.push_back({1, {{-1, 0, 0}, 5.0}, 1, 100, 10, 150, 60, 300});
  planes.push_back({2, {{1, 0, 0}, 6.0}, 1, 7, 480, 630, 60, 300});
  planes.push_back({3, {{1, 0, 0}, 7.0}, 1, 7, 400, 470, 60, 200});
  planes.push_back({4, {{1, 0, 0}, 6.5}, 8, 100, 480, 630, 60, 300});
  planes.push_back({5, {{1, 0, 0}, 8.0}, 8, 100, 400, 470, 60, 200});
  return planes;
}

// Exact observations of pair (k-1, k): a 16 px grid over each plane's region,
// the later pixel's ray cut with the plane, projected into anchor k-1.
std::vector<WindowPlaneObservation> Observe(const std::vector<WorldPlane>& planes, int k,
                                            double noise_px, std::mt19937* rng) {
  const Intrinsics K = TestIntrinsics();
  const Rigid3d world_from_b = TruePose(k), world_from_a = TruePose(k - 1);
  const Rigid3d a_from_b = world_from_a.Inverse() * world_from_b;
  std::normal_distribution<double> noise(0.0, noise_px);
  std::vector<WindowPlaneObservation> out;
  for (const WorldPlane& wp : planes) {
    if (k < wp.first || k > wp.last) continue;
    const Plane3d pb = PlaneInCamera(world_from_b, wp.plane, true);
    WindowPlaneObservation o;
    o.plane_id = wp.id;
    for (double v = wp.v_min; v <= wp.v_max; v += 16) {
      for (double u = wp.u_min; u <= wp.u_max; u += 16) {
        const Eigen::Vector3d ray = K.Unproject({u, v});
        const double inv_depth = pb.InverseDepth().dot(ray);
        if (!(inv_depth > 1.0 / 80.0)) continue;  // behind or beyond 80 m
        const Eigen::Vector3d Xa = a_from_b * (ray / inv_depth);
        if (!(Xa.z() > 0.5)) continue;
        const Eigen::Vector2d xa(K.fx_px * Xa.x() / Xa.z() + K.cx_px,
                                 K.fy_px * Xa.y() / Xa.z() + K.cy_px);
        o.x_later_px.push_back({u, v});
        o.x_earlier_px.push_back(
            noise_px > 0 ? Eigen::Vector2d(xa.x() + noise(*rng), xa.y() + noise(*rng)) : xa);
        o.variance_px2.push_back(0.25 * 0.25 / 3);
      }
    }
    if (o.x_later_px.size() >= 4) out.push_back(std::move(o));
  }
  return out;
}

// pi of each observed plane in anchor k's camera, its distance off by `scale`.
std::map<int, Eigen::Vector3d> Guesses(const std::vector<WorldPlane>& planes, int k, double scale) {
  std::map<int, Eigen::Vector3d> g;
  for (const WorldPlane& wp : planes) {
    if (k < wp.first || k > wp.last) continue;
    g[wp.id] = PlaneInCamera(TruePose(k), wp.plane, true).InverseDepth() / scale;
  }
  return g;
}

double StepLength(const WindowRefiner& r, size_t k) {
  return (r.world_from_cam(k).translation - r.world_from_cam(k - 1).translation).norm();
}

// Streams a drive through the refiner as the pipeline does: each new anchor's
// pose guess is the last refined pose composed with the true step scaled by
// `step_error` at anchor `bad_anchor` (the filter's jump at a plane turnover)
// and new planes come with the same wrong scale. Returns the worst
// |refined step / true step - 1| of the newest step over the drive.
double WorstNewestStepError(const std::vector<WorldPlane>& planes, int anchors, int bad_anchor,
                            double step_error, double noise_px, WindowRefinerOptions options) {
  std::mt19937 rng(7);
  WindowRefiner refiner(TestIntrinsics(), options);
  refiner.Push(0, 0.0, TruePose(0), {}, {}, -1);
  double worst = 0;
  for (int k = 1; k < anchors; ++k) {
    const Rigid3d true_step = TruePose(k - 1).Inverse() * TruePose(k);
    Rigid3d step = true_step;
    const double s = k == bad_anchor ? step_error : 1.0;
    step.translation *= s;
    const Rigid3d guess = refiner.world_from_cam(refiner.size() - 1) * step;
    refiner.Push(k, k * kDtS, guess, Observe(planes, k, noise_px, &rng), Guesses(planes, k, s),
                 planes.front().id == 0 ? 0 : -1);
    WindowRefineReport report;
    EXPECT_TRUE(refiner.Refine(&report).ok());
    EXPECT_TRUE(report.solved);
    const double err = std::abs(StepLength(refiner, refiner.size() - 1) / kStepM - 1.0);
    worst = std::max(worst, err);
  }
  return worst;
}

TEST(WindowRefinerTest, RecoversPosesAndPlanesWithTheOldestPoseFixed) {
  const std::vector<WorldPlane> planes = Street(true);
  WindowRefiner refiner(TestIntrinsics());
  std::mt19937 rng(1);
  // Exact first two anchors (the gauge), then guesses off by 8 % in scale and 1 deg.
  refiner.Push(0, 0.0, TruePose(0), {}, {}, -1);
  refiner.Push(1, kDtS, TruePose(1), Observe(planes, 1, 0, &rng), Guesses(planes, 1, 1.0), 0);
  for (int k = 2; k < 6; ++k) {
    Rigid3d guess = TruePose(k);
    guess.translation += (TruePose(k).translation - TruePose(1).translation) * 0.08;
    guess.rotation =
        guess.rotation * Eigen::Quaterniond(Eigen::AngleAxisd(0.017, Eigen::Vector3d::UnitX()));
    refiner.Push(k, k * kDtS, guess, Observe(planes, k, 0, &rng), Guesses(planes, k, 1.08), 0);
  }
  const Rigid3d oldest_before = refiner.world_from_cam(0);
  WindowRefineReport report;
  ASSERT_TRUE(refiner.Refine(&report).ok());
  ASSERT_TRUE(report.solved);
  EXPECT_EQ(report.anchors, 6);
  EXPECT_GT(report.residuals, 200);
  EXPECT_LT(report.final_rms, 0.05 * report.initial_rms);
  // Gauge: the oldest pose is untouched.
  EXPECT_EQ(refiner.world_from_cam(0).translation, oldest_before.translation);
  EXPECT_EQ(refiner.world_from_cam(0).rotation.coeffs(), oldest_before.rotation.coeffs());
  for (size_t k = 1; k < refiner.size(); ++k) {
    const Rigid3d truth = TruePose(static_cast<int>(refiner.index(k)));
    EXPECT_LT((refiner.world_from_cam(k).translation - truth.translation).norm(), 0.01 * kStepM * k)
        << "anchor " << k;
    EXPECT_LT(refiner.world_from_cam(k).rotation.angularDistance(truth.rotation), 1e-3);
  }
  // The road: 1.5 m below the newest camera.
  ASSERT_TRUE(report.road_in_window);
  EXPECT_NEAR(report.road_distance, 1.5, 0.015);
  EXPECT_EQ(report.road_pairs, 5);
}

// The scale must not jump when the observed planes turn over: with no road,
// the right-hand walls are replaced by new ones at anchor 8 and the
// predictor's step and the new planes come 30 % too long (the filter's jump
// the issue reports). The window (planes seen across it, the motion prior)
// keeps the newest step within 3 % of the truth; without the motion prior
// (sigma huge) nothing ties the new planes' scale to the old and the jump
// stays.
TEST(WindowRefinerTest, ScaleHoldsThroughAPlaneTurnover) {
  const std::vector<WorldPlane> planes = Street(false);
  WindowRefinerOptions o;
  // A wall seen across the window carries the scale.
  EXPECT_LT(WorstNewestStepError(planes, 16, 8, 1.3, 0.1, o), 0.03);
  // Every plane turns over at once: the motion prior alone carries it.
  const std::vector<WorldPlane> right_only(planes.begin() + 1, planes.end());
  EXPECT_LT(WorstNewestStepError(right_only, 16, 8, 1.3, 0.1, o), 0.03);
  // Without the motion prior nothing ties the new planes' scale to the old
  // steps: the jump stays (so the bound above is the prior's doing).
  o.speed_change_rel_per_sqrt_s = 1e3;
  o.angular_rate_change_rad_s_per_sqrt_s = 1e3;
  EXPECT_GT(WorstNewestStepError(right_only, 16, 8, 1.3, 0.1, o), 0.2);
}

// The road's attitude (gauge (e)) and height (c) are the trajectory's, not
// the window's. Short baselines, as H.264 IPPP's one-frame pairs: 5 cm steps
// at 30 fps over a road 1.5 m below, the road alone, blocks with 1 px of
// noise (0.3-4 px of flow). Every 12 anchors the window restarts (Reset: the
// pipeline does so after a step without planes) and takes the road from the
// filter's guess, which has drifted: tilted by 3 deg in pitch and 10 % too
// near. Returns the angle (deg) between the newest camera's refined road
// normal and the truth, and the road's distance from it relative to the
// height first held.
struct RoadAfterRestarts {
  double attitude_error_deg = 180.0, height_ratio = 0.0;
  // The largest height change of the newest camera over the stream, m (the
  // true cameras stay at one height: y = 0).
  double max_height_change_m = 0.0;
  // RMS over the stream of the newest step's height change, m (true: 0).
  double rms_step_height_change_m = 0.0;
};
RoadAfterRestarts StreamRoadWithRestarts(int anchors, const WindowRefinerOptions& options,
                                         bool restarts = true) {
  const Intrinsics K = TestIntrinsics();
  constexpr double kDt = 1.0 / 30.0, kStep = 0.05;
  const Plane3d road_world{{0, 1, 0}, 1.5};  // camera y is down: the road 1.5 m below
  auto pose = [&](int k) {
    Rigid3d p;
    p.translation = Eigen::Vector3d(0, 0, kStep * k);
    return p;
  };
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 1.0);
  WindowRefiner refiner(K, options);
  refiner.Push(0, 0.0, pose(0), {}, {}, -1);
  std::optional<double> held_height;
  double max_height_change_m = 0.0, step_sq_sum = 0.0;
  int steps = 0;
  for (int k = 1; k < anchors; ++k) {
    const Plane3d pb = PlaneInCamera(pose(k), road_world, true);
    const Rigid3d a_from_b = pose(k - 1).Inverse() * pose(k);
    WindowPlaneObservation o;
    o.plane_id = 0;
    for (double v = 300; v <= 470; v += 16) {
      for (double u = 40; u <= 600; u += 16) {
        const Eigen::Vector3d ray = K.Unproject({u, v});
        const Eigen::Vector3d Xa = a_from_b * (ray / pb.InverseDepth().dot(ray));
        o.x_later_px.push_back({u, v});
        o.x_earlier_px.push_back({K.fx_px * Xa.x() / Xa.z() + K.cx_px + noise(rng),
                                  K.fy_px * Xa.y() / Xa.z() + K.cy_px + noise(rng)});
        o.variance_px2.push_back(0.25 * 0.25 / 3);
      }
    }
    std::map<int, Eigen::Vector3d> guess{{0, pb.InverseDepth()}};
    if (restarts && k % 12 == 0) {  // the window restarts on the filter's drifted road
      const Rigid3d newest = refiner.world_from_cam(refiner.size() - 1);
      refiner.Reset();
      refiner.Push(k - 1, (k - 1) * kDt, newest, {}, {}, -1);
      const Eigen::Vector3d tilted =
          Eigen::AngleAxisd(DegToRad(3.0), Eigen::Vector3d::UnitX()) * pb.normal;
      guess[0] = tilted / (0.9 * pb.distance);
    }
    const Rigid3d step_guess = refiner.world_from_cam(refiner.size() - 1) * a_from_b;
    std::vector<WindowPlaneObservation> obs{o};
    refiner.Push(k, k * kDt, step_guess, std::move(obs), guess, 0);
    WindowRefineReport report;
    EXPECT_TRUE(refiner.Refine(&report).ok());
    if (!held_height) held_height = refiner.road_height();
    const size_t n = refiner.size();
    max_height_change_m =
        std::max(max_height_change_m, std::abs(refiner.world_from_cam(n - 1).translation.y()));
    if (n >= 2) {
      const double dy = refiner.world_from_cam(n - 1).translation.y() -
                        refiner.world_from_cam(n - 2).translation.y();
      step_sq_sum += dy * dy;
      ++steps;
    }
  }
  RoadAfterRestarts r;
  r.max_height_change_m = max_height_change_m;
  r.rms_step_height_change_m = steps > 0 ? std::sqrt(step_sq_sum / steps) : 0.0;
  const std::optional<Eigen::Vector3d> road = refiner.RoadInNewest();
  EXPECT_TRUE(road.has_value());
  if (!road) return r;
  r.attitude_error_deg = AngleBetweenDeg(*road, Eigen::Vector3d::UnitY());
  if (held_height) r.height_ratio = 1.0 / road->norm() / *held_height;
  // The references outlive the restarts.
  EXPECT_EQ(refiner.road_height(), held_height);
  return r;
}

// With the attitude prior on (the default), the restarts take neither the
// drifted tilt nor the drifted height: both references hold. They are the
// mean over the first road_reference_solves full-window solves; taken from
// the road's first solve alone (one 5 cm baseline), the attitude was 7 deg
// off here and held the road there (7.3 deg at the end).
TEST(WindowRefinerTest, RoadAttitudeAndHeightOutliveWindowRestarts) {
  WindowRefinerOptions on, without;
  without.road_attitude_sigma_deg = 0;
  const RoadAfterRestarts with = StreamRoadWithRestarts(60, on);
  const RoadAfterRestarts off = StreamRoadWithRestarts(60, without);
  std::printf(
      "after 60 anchors and 4 restarts: attitude error %.2f deg, height %.3f of the held "
      "one (without the attitude prior, which holds no height: %.2f deg)\n",
      with.attitude_error_deg, with.height_ratio, off.attitude_error_deg);
  EXPECT_LT(with.attitude_error_deg, 1.2);
  EXPECT_LT(with.attitude_error_deg, off.attitude_error_deg + 0.2);
  EXPECT_NEAR(with.height_ratio, 1.0, 0.02);
}

// The road's level (f) alone (the attitude prior off) on a noisy one-frame
// road stream (5 cm steps, 1 px noise). The default sigma (1.5 cm per step
// at 1.5 m) is far above what these vectors leave open (~2 mm per step), so
// the prior is tightened to 0.75 mm here to see it act: the steps' height
// changes shrink toward 0, the truth, and so does the height's drift.
TEST(WindowRefinerTest, RoadLevelKeepsTheCamerasAtTheirHeight) {
  WindowRefinerOptions on, without;
  on.road_attitude_sigma_deg = without.road_attitude_sigma_deg = 0;
  on.road_level_rel_sigma = 0.0005;
  without.road_level_rel_sigma = 0;
  const RoadAfterRestarts with = StreamRoadWithRestarts(60, on, /*restarts=*/false);
  const RoadAfterRestarts off = StreamRoadWithRestarts(60, without, /*restarts=*/false);
  std::printf(
      "over 60 anchors (3 m), with the level prior / without: step height change RMS %.5f / "
      "%.5f m, largest height change %.4f / %.4f m, road attitude error %.2f / %.2f deg\n",
      with.rms_step_height_change_m, off.rms_step_height_change_m, with.max_height_change_m,
      off.max_height_change_m, with.attitude_error_deg, off.attitude_error_deg);
  // Measured: 1.2 / 2.1 mm and 3.6 / 6.7 cm.
  EXPECT_LT(with.rms_step_height_change_m, 0.7 * off.rms_step_height_change_m);
  EXPECT_LT(with.max_height_change_m, 0.7 * off.max_height_change_m);
}

// The references are taken after road_reference_solves full-window solves,
// then held; Rescale scales the height, not the attitude; Reset keeps both.
TEST(WindowRefinerTest, RoadReferencesFollowRescaleAndSurviveReset) {
  const std::vector<WorldPlane> planes = Street(true);
  const WindowRefinerOptions on;
  WindowRefiner refiner(TestIntrinsics(), on);
  std::mt19937 rng(5);
  refiner.Push(0, 0.0, TruePose(0), {}, {}, -1);
  // The window is full from anchor window_anchors - 1 on.
  const int taken = on.window_anchors - 2 + on.road_reference_solves;
  for (int k = 1; k <= taken + 2; ++k) {
    refiner.Push(k, k * kDtS, TruePose(k), Observe(planes, k, 0, &rng), Guesses(planes, k, 1.0), 0);
    WindowRefineReport report;
    ASSERT_TRUE(refiner.Refine(&report).ok());
    EXPECT_EQ(refiner.road_normal_cam().has_value(), k >= taken) << "anchor " << k;
  }
  ASSERT_TRUE(refiner.road_height().has_value());
  ASSERT_TRUE(refiner.road_normal_cam().has_value());
  EXPECT_NEAR(*refiner.road_height(), 1.5, 0.015);
  EXPECT_LT(AngleBetweenDeg(*refiner.road_normal_cam(), Eigen::Vector3d::UnitY()), RadToDeg(1e-3));
  const Eigen::Vector3d normal = *refiner.road_normal_cam();
  refiner.Rescale(2.0);
  refiner.Reset();
  EXPECT_EQ(refiner.size(), 0u);
  ASSERT_TRUE(refiner.road_height().has_value());
  EXPECT_NEAR(*refiner.road_height(), 3.0, 0.03);
  EXPECT_EQ(*refiner.road_normal_cam(), normal);
}

// A window that cannot fit its vectors (here 40 px of noise on every block)
// is not used: rejected, the poses as pushed. The same pair with 0.25 px of
// noise is solved.
TEST(WindowRefinerTest, ASolveThatDoesNotFitIsRejected) {
  const std::vector<WorldPlane> planes = Street(true);
  for (const double noise_px : {40.0, 0.25}) {
    WindowRefiner refiner(TestIntrinsics());
    std::mt19937 rng(9);
    refiner.Push(0, 0.0, TruePose(0), {}, {}, -1);
    const Rigid3d guess = TruePose(1);
    refiner.Push(1, kDtS, guess, Observe(planes, 1, noise_px, &rng), Guesses(planes, 1, 1.0), 0);
    WindowRefineReport report;
    ASSERT_TRUE(refiner.Refine(&report).ok());
    std::printf("noise %.2f px: final rms %.2f\n", noise_px, report.final_rms);
    const bool fits = noise_px < 1.0;
    EXPECT_EQ(report.solved, fits);
    EXPECT_EQ(report.rejected, !fits);
    EXPECT_EQ(report.final_rms > WindowRefinerOptions{}.max_final_rms, !fits);
    if (!fits) {
      EXPECT_EQ(refiner.world_from_cam(1).translation, guess.translation);
      EXPECT_TRUE(refiner.world_from_cam(1).rotation.isApprox(guess.rotation, 0.0));
    }
  }
}

TEST(WindowRefinerTest, WindowIsBounded) {
  const std::vector<WorldPlane> planes = Street(true);
  WindowRefinerOptions o;
  o.window_anchors = 4;
  WindowRefiner refiner(TestIntrinsics(), o);
  std::mt19937 rng(3);
  refiner.Push(0, 0.0, TruePose(0), {}, {}, -1);
  for (int k = 1; k < 12; ++k) {
    refiner.Push(k, k * kDtS, TruePose(k), Observe(planes, k, 0, &rng), Guesses(planes, k, 1.0), 0);
    EXPECT_LE(refiner.size(), 4u);
  }
  EXPECT_EQ(refiner.index(0), 8);
  EXPECT_EQ(refiner.index(3), 11);
}

TEST(WindowRefinerTest, OptionsCheck) {
  EXPECT_TRUE(WindowRefinerOptions{}.Check().ok());
  WindowRefinerOptions off;
  off.road_attitude_sigma_deg = 0.0;
  off.road_level_rel_sigma = 0.0;
  EXPECT_TRUE(off.Check().ok());
  // Each of these alone is refused.
  const std::vector<std::function<void(WindowRefinerOptions*)>> bad = {
      [](WindowRefinerOptions* o) { o->window_anchors = 2; },
      [](WindowRefinerOptions* o) { o->huber_k = 0; },
      [](WindowRefinerOptions* o) { o->metric_gauge_step_rel_sigma = 0; },
      [](WindowRefinerOptions* o) { o->road_attitude_sigma_deg = -1.0; },
      [](WindowRefinerOptions* o) { o->road_level_rel_sigma = -0.01; },
      [](WindowRefinerOptions* o) { o->road_reference_solves = 0; },
      [](WindowRefinerOptions* o) { o->reassociate_max_distance_ratio = 1.0; },
      [](WindowRefinerOptions* o) { o->max_final_rms = 0.0; },
  };
  for (size_t i = 0; i < bad.size(); ++i) {
    WindowRefinerOptions o;
    bad[i](&o);
    EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument) << "case " << i;
  }
}

// PlaneTransferCost's analytic Jacobian against Ceres' automatic
// differentiation of the same residual and against central finite
// differences, on the four quaternion coordinates as Ceres sees them, with
// some parameter blocks constant (no Jacobian asked for).
// A plane-transfer block with the window's oldest camera at TruePose(r) and
// `n` macroblocks at random rays and earlier pixels, weights in [0.1, 0.9].
PlaneTransferData RandomTransferData(int r, int n, double fy, std::mt19937* rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PlaneTransferData data;
  data.fx = 457.0;
  data.fy = fy;
  data.cx = 319.5;
  data.cy = 239.5;
  const Rigid3d world_from_r = TruePose(r);
  data.R_rw = world_from_r.R().transpose();
  data.c_wr = world_from_r.translation;
  for (int j = 0; j < n; ++j) {
    const Eigen::Vector3d ray(0.6 * u(*rng), 0.4 * u(*rng), 1.0);
    const Eigen::Vector2d x_earlier(320 + 200 * u(*rng), 240 + 150 * u(*rng));
    data.mbs.push_back({ray, x_earlier, 0.5 + 0.4 * u(*rng)});
  }
  return data;
}

TEST(PlaneTransferCostTest, JacobianMatchesAutoDiffAndFiniteDifferences) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PlaneTransferData data = RandomTransferData(2, 12, 457.0, &rng);
  // Earlier / later anchors 3 and 4, perturbed; a wall 5 m to the left in r.
  const Rigid3d pa = TruePose(3), pb = TruePose(4);
  Eigen::Quaterniond qa = pa.rotation, qb = pb.rotation;
  qa.coeffs() += 0.01 * Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng));
  qb.coeffs() += 0.01 * Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng));
  Eigen::Vector3d ca = pa.translation + 0.05 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  Eigen::Vector3d cb = pb.translation + 0.05 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  Eigen::Vector3d pi(-0.2 + 0.01 * u(rng), 0.01 * u(rng), 0.02);
  std::vector<double*> blocks = {qa.coeffs().data(), ca.data(), qb.coeffs().data(), cb.data(),
                                 pi.data()};
  const int sizes[5] = {4, 3, 4, 3, 3};
  const int n = 2 * static_cast<int>(data.mbs.size());

  PlaneTransferCost analytic(data);
  ceres::AutoDiffCostFunction<PlaneTransferResidual, ceres::DYNAMIC, 4, 3, 4, 3, 3> autodiff(
      new PlaneTransferResidual{data}, n);
  ASSERT_EQ(analytic.num_residuals(), n);
  std::vector<std::vector<double>> ja(5), jd(5);
  std::vector<double*> ja_ptr(5), jd_ptr(5);
  for (int b = 0; b < 5; ++b) {
    ja[b].assign(n * sizes[b], 0.0);
    jd[b].assign(n * sizes[b], 0.0);
    ja_ptr[b] = ja[b].data();
    jd_ptr[b] = jd[b].data();
  }
  std::vector<double> ra(n), rd(n);
  ASSERT_TRUE(analytic.Evaluate(blocks.data(), ra.data(), ja_ptr.data()));
  ASSERT_TRUE(autodiff.Evaluate(blocks.data(), rd.data(), jd_ptr.data()));
  for (int i = 0; i < n; ++i) EXPECT_NEAR(ra[i], rd[i], 1e-9 * (1.0 + std::abs(rd[i])));
  for (int b = 0; b < 5; ++b) {
    for (int k = 0; k < n * sizes[b]; ++k) {
      EXPECT_NEAR(ja[b][k], jd[b][k], 1e-8 * (1.0 + std::abs(jd[b][k]))) << "block " << b;
    }
    // Central differences, h = 1e-6 on each coordinate.
    for (int c = 0; c < sizes[b]; ++c) {
      const double keep = blocks[b][c], h = 1e-6;
      std::vector<double> plus(n), minus(n);
      blocks[b][c] = keep + h;
      ASSERT_TRUE(analytic.Evaluate(blocks.data(), plus.data(), nullptr));
      blocks[b][c] = keep - h;
      ASSERT_TRUE(analytic.Evaluate(blocks.data(), minus.data(), nullptr));
      blocks[b][c] = keep;
      for (int i = 0; i < n; ++i) {
        const double numeric = (plus[i] - minus[i]) / (2 * h);
        EXPECT_NEAR(ja[b][i * sizes[b] + c], numeric, 1e-4 * (1.0 + std::abs(numeric)))
            << "block " << b << " coordinate " << c << " residual " << i;
      }
    }
  }
  // Constant blocks (null Jacobians) leave the others' unchanged.
  std::vector<double> ja_q(n * 4, 0.0);
  std::vector<double*> some = {nullptr, nullptr, ja_q.data(), nullptr, nullptr};
  ASSERT_TRUE(analytic.Evaluate(blocks.data(), ra.data(), some.data()));
  for (int k = 0; k < n * 4; ++k) EXPECT_EQ(ja_q[k], ja[2][k]);
  // A macroblock behind the earlier camera: no evaluation.
  data.mbs[0].ray = Eigen::Vector3d(0, 0, -1);
  EXPECT_FALSE(PlaneTransferCost(data).Evaluate(blocks.data(), ra.data(), nullptr));
}

// The normal equations the refiner's solver takes from PlaneTransferCost
// (J^T J = D^T N D, J^T r = D^T G, plane_transfer_cost.h) against J^T J and
// J^T r formed from its Jacobian (checked above against autodiff and finite
// differences), on 60 macroblocks of varied weight and fx != fy.
TEST(PlaneTransferCostTest, NormalEquationsEqualThoseOfTheJacobian) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PlaneTransferData data = RandomTransferData(1, 60, 455.0, &rng);
  const Rigid3d pa = TruePose(2), pb = TruePose(3);
  Eigen::Quaterniond qa = pa.rotation, qb = pb.rotation;
  qb.coeffs() += 0.01 * Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng));
  Eigen::Vector3d ca = pa.translation, cb = pb.translation + Eigen::Vector3d(0.03, -0.02, 0.04);
  Eigen::Vector3d pi(0.01, -0.6, 0.02);  // the road 1.6 m below r
  const std::vector<double*> blocks = {qa.coeffs().data(), ca.data(), qb.coeffs().data(), cb.data(),
                                       pi.data()};
  const PlaneTransferCost cost(data);
  // r and J (n x 17, the blocks' columns side by side) from Evaluate.
  const int n = cost.num_residuals();
  Eigen::VectorXd rv(n);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Jq_a(n, 4), Jc_a(n, 3),
      Jq_b(n, 4), Jc_b(n, 3), Jpi(n, 3);
  double* jac[5] = {Jq_a.data(), Jc_a.data(), Jq_b.data(), Jc_b.data(), Jpi.data()};
  ASSERT_TRUE(cost.Evaluate(blocks.data(), rv.data(), jac));
  Eigen::MatrixXd J(n, 17);
  J << Jq_a, Jc_a, Jq_b, Jc_b, Jpi;
  const Eigen::MatrixXd JtJ = J.transpose() * J;
  const Eigen::VectorXd Jtr = J.transpose() * rv;

  double half = -1;
  Eigen::VectorXd g;
  Eigen::MatrixXd H;
  ASSERT_TRUE(cost.EvaluateNormalEquations(blocks.data(), &half, &g, &H));
  EXPECT_NEAR(half, 0.5 * rv.squaredNorm(), 1e-12 * rv.squaredNorm());
  EXPECT_GT(half, 1.0);  // the perturbed poses leave residuals
  ASSERT_EQ(g.size(), 17);
  ASSERT_EQ(H.rows(), 17);
  ASSERT_EQ(H.cols(), 17);
  EXPECT_LT((g - Jtr).norm(), 1e-9 * Jtr.norm());
  EXPECT_LT((H - JtJ).norm(), 1e-9 * JtJ.norm());
  EXPECT_LT((H - H.transpose()).norm(), 1e-12 * JtJ.norm());

  data.mbs[5].ray = Eigen::Vector3d(0, 0, -1);  // behind the earlier camera
  EXPECT_FALSE(PlaneTransferCost(data).EvaluateNormalEquations(blocks.data(), &half, &g, &H));
}

}  // namespace
}  // namespace slapse
