// Ground truth of a simulated drive, as written beside the video and read back
// by tests, benchmarks and evaluation.
//
// Files in a drive directory (all in the world frame: z up, road plane z = 0):
//   trajectory_tum.txt  TUM: "timestamp_s tx ty tz qx qy qz qw", world_from_cam, one line a frame
//   intrinsics.json     fx_px, fy_px, cx_px, cy_px, width_px, height_px (core/common/camera.h)
//   planes.json         every plane: id, kind, normal_world, distance_m (n . X = d), polygons
//   mb_labels.txt       per frame, per 16x16 macroblock: which plane it sees (see MbLabel)
//   mb_mixed.txt        per mixed macroblock: the labels its pixels see and their shares
//                       (optional: drives simulated before it existed have none)
//   meta.json           seed, codec, GOP, fps, frame count, distance driven, timings
#pragma once

#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"

namespace slapse {

// kGuardRail: the face of a guard rail's beam (a narrow vertical strip);
// kObject: a planar face of a small object (a parked car's side, a kiosk).
enum class PlaneKind { kRoad, kFacade, kBackground, kGuardRail, kObject };
const char* PlaneKindName(PlaneKind kind);

struct GtPlane {
  int id = -1;
  PlaneKind kind = PlaneKind::kFacade;
  // Unit normal in the world frame, pointing to the side the camera sees;
  // points X on the plane satisfy normal_world . X = distance_m.
  Eigen::Vector3d normal_world = Eigen::Vector3d::UnitZ();
  double distance_m = 0.0;
  // Extent: one or more convex polygons (world frame) lying on the plane.
  std::vector<std::vector<Eigen::Vector3d>> polygons_world;
};

// Macroblock labels: a plane id (>= 0) when at least kMbLabelCoverage of the
// block's pixels see that plane, else one of these.
enum MbLabel : int { kMbSky = -1, kMbClutter = -2, kMbMixed = -3 };
constexpr double kMbLabelCoverage = 0.9;

// One label seen by part of a macroblock: `share` of its pixels (supersamples).
struct MbShare {
  int label = kMbSky;  // plane id, kMbSky or kMbClutter
  float share = 0.0f;  // (0, 1]
};

struct GtFrame {
  double timestamp_s = 0.0;
  Rigid3d world_from_cam;
  std::vector<int> mb_labels;  // row-major, mb_cols * mb_rows
  // For the blocks labelled kMbMixed (key: row-major MB index): every label
  // their pixels see, largest share first; the shares sum to 1. A block on the
  // seam of two flush facades is mixed yet all on planes (lab/eval/plane_eval.h).
  std::map<int, std::vector<MbShare>> mixed_shares;
};

struct GroundTruth {
  Intrinsics intrinsics;
  std::vector<GtPlane> planes;  // indexed by id: planes[i].id == i
  std::vector<GtFrame> frames;  // display order, frame i = decoded frame i
  int mb_cols = 0, mb_rows = 0;
  double fps = 0.0;

  // Label of the macroblock containing pixel (x, y) in frame `frame`.
  int LabelAt(int frame, double x_px, double y_px) const;

  // Where pixel x of frame `frame`, taken to lie on plane `plane_id`, appears
  // in frame `other`, by the true poses and plane: the ray through x meets the
  // plane, the point is projected into `other`. False when the ray misses the
  // plane or the point is behind either camera (closer than 0.1 m).
  bool TransferThroughPlane(int plane_id, int frame, int other, const Eigen::Vector2d& x_px,
                            Eigen::Vector2d* x_other_px) const;
};

Status SaveGroundTruth(const GroundTruth& gt, const std::string& dir);
StatusOr<GroundTruth> LoadGroundTruth(const std::string& dir);

}  // namespace slapse
