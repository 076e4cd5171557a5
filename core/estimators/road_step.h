// The road seen from the frames between two anchors: the step length over the
// road's distance, from the short-span vectors of those frames.
//
// Why: in an IBBBP stream the anchors are four frames apart, and at speed
// the near road moves beyond the encoder's search between them (on a 30 fps
// MPEG-2 rural drive: 10 % of the road's four-frame vectors within 2 px of
// the truth where the true flow is 32-64 px, 64 % of its one-frame ones;
// `bench/mv_accuracy --span 1|4`). The road is then not extracted from
// the anchor pair, the filter coasts on it and the step length is the
// motion model's. The B frames next to the earlier anchor still follow the
// road: their past vectors span one or two frames.
//
// Frames and model. C_e is the earlier anchor's camera, C_l the later one's,
// and (R, t) the step prev_from_cur: X_e = R X_l + t (core/ekf/plane_ekf.h).
// A frame between them at the fraction f of the step's time sits at
//   X_e = R_f X_f + f t,  R_f = Exp(f Log R)
// (constant velocity within the step). The road is the plane
// pi_e^T X_e = 1 of C_e (pi_e = n / d, n its unit normal towards it, d its
// distance); the estimate is
//   q = |t| pi_e = (|t| / d) n,
// whose length s = |t| / d is the step length over the road's distance. A
// block centre x_f of the frame (ray r = K^-1 [x_f; 1], b = R_f r) on the
// road is the point
//   X_e / |t| = (1 - f q^T u) / (q^T b) b + f u,   u = t / |t|,
// whose pixel in the earlier anchor its past vector points to. Valid where
// q^T b > 0 (the ray meets the road in front) and 1 - f q^T u > 0.
//
// The fit holds q perpendicular to u (the car drives along its road, the
// filter's road-height rule), two parameters: q = B w with B an orthonormal
// basis of u's complement (TangentBasis). Fitting all three put the far
// road's tilt against s (fitted step lengths scattered by +-15 % on
// 320x240 drives); holding the normal at the filter's road instead went
// wrong where that normal had drifted while the road coasted (a rural
// tuning drive: ATE 0.29 -> 2.8 %). docs/METHOD.md "The road from the
// frames between the anchors".
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/status.h"

namespace slapse {

// A past vector of a frame between the anchors, into the earlier anchor.
struct InterFrameVector {
  Eigen::Vector2d x_frame_px = Eigen::Vector2d::Zero();    // block centre in the frame
  Eigen::Vector2d x_earlier_px = Eigen::Vector2d::Zero();  // its content in the earlier anchor
  double fraction = 0.0;  // (t_frame - t_earlier) / (t_later - t_earlier), in (0, 1)
};

struct RoadStepOptions {
  // A vector within this distance (px) of the road's prediction is an inlier.
  double inlier_px = 1.5;
  // Road hypotheses from pairs of vectors (RANSAC, fixed seed): at most
  // `iterations`, fewer once the best one's inlier share makes an all-inlier
  // pair among those tried this likely.
  int iterations = 150;
  double confidence = 0.999;
  // Hypotheses and the result must be road-like (core/common/road.h, down =
  // the earlier camera's +y axis) within this angle.
  double road_max_angle_deg = 20.0;
  // Fewer inliers: no estimate.
  int min_inliers = 30;
  // Vectors shorter than this (px) are not used (see EstimateRoadStep).
  double min_flow_px = 0.5;
  // Standard deviation of one vector's error for the estimate's covariance,
  // px, and the factor the covariance is inflated by (neighbouring blocks'
  // vectors err together: the encoder's search shares its predictors).
  double sigma_px = 1.0;
  double inflation = 4.0;
  // InvalidArgument (prefixed with `who`) unless inlier_px > 0, iterations
  // >= 1, confidence in (0, 1), road_max_angle_deg in (0, 90), min_inliers >= 3, sigma_px > 0,
  // inflation >= 1 and min_flow_px >= 0.
  Status Check(const std::string& who = "RoadStepOptions") const;
};

struct RoadStepReport {
  bool success = false;  // false: no road-like plane with min_inliers vectors
  Eigen::Vector3d q = Eigen::Vector3d::Zero();  // |t| pi_e (file comment)
  // Its covariance (inflated); rank 2: q is held perpendicular to u.
  Eigen::Matrix3d q_cov = Eigen::Matrix3d::Zero();
  int inliers = 0;
  double rms_px = 0.0;  // the inliers' residual RMS
};

// The earlier-anchor pixel the model predicts for a block centre of the
// frame at `fraction` (R_fraction = Exp(fraction Log R)); false where the
// ray misses the road (file comment).
bool PredictRoadPixel(const Eigen::Matrix3d& K, const Eigen::Matrix3d& K_inv,
                      const Eigen::Matrix3d& R_fraction, const Eigen::Vector3d& u, double fraction,
                      const Eigen::Vector3d& q, const Eigen::Vector2d& x_frame_px,
                      Eigen::Vector2d* x_earlier_px);

// Estimates q from the vectors, given the step's rotation R and the direction
// of its translation u (unit), both prev_from_cur. InvalidArgument for bad
// options, a non-unit u or a fraction outside (0, 1); a scene without such a
// road is success = false.
StatusOr<RoadStepReport> EstimateRoadStep(const std::vector<InterFrameVector>& vectors,
                                          const Intrinsics& intrinsics, const Eigen::Matrix3d& R,
                                          const Eigen::Vector3d& u,
                                          const RoadStepOptions& options = {});

}  // namespace slapse
