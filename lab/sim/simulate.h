// A simulated drive: scene + camera path + rendering + encoding + ground truth.
//
//   SimulateOptions opt;
//   opt.seed = 7;
//   opt.output_dir = "/tmp/drive7";
//   SimulateReport report;
//   Status s = SimulateDrive(opt, &report);
//   // /tmp/drive7: drive.ts, trajectory_tum.txt, intrinsics.json, planes.json,
//   //              mb_labels.txt, mb_mixed.txt, meta.json (formats in
//   //              lab/gt/ground_truth.h)
#pragma once

#include <cstdint>
#include <string>

#include "core/common/camera.h"
#include "core/common/status.h"
#include "lab/codec/video_encoder.h"
#include "lab/sim/camera_path.h"
#include "lab/sim/renderer.h"
#include "lab/sim/scene.h"

namespace slapse {

struct SimulateOptions {
  uint64_t seed = 1;
  double duration_s = 10.0;
  double fps = 30.0;
  int width_px = 640, height_px = 480;
  double hfov_deg = 70.0;
  double min_speed_mps = 25.0 / 3.6, max_speed_mps = 50.0 / 3.6;
  bool trees = true;
  int supersampling = 2;
  // The scene's layout (lab/sim/scene.h SceneKind; its ranges from
  // SceneOptionsFor) and whether its look varies with the seed.
  SceneKind scene_kind = SceneKind::kUrban;
  bool appearance_variety = false;
  // The camera's height above the road and its fixed downward pitch (negative:
  // up), each drawn uniformly from its range by the path's seed.
  double camera_height_min_m = 1.3, camera_height_max_m = 1.6;
  double pitch_down_min_deg = 2.0, pitch_down_max_deg = 5.0;
  // Peak vertical bounce of the camera on the car's suspension (PathOptions::bounce_m).
  double bounce_m = PathOptions().bounce_m;
  // The camera's optics and sensor after rendering: a Gaussian blur (sigma,
  // output pixels; 0: none) and additive Gaussian noise per pixel and channel
  // (sigma, 8-bit levels; 0: none; seeded per frame from the seed).
  double blur_px = 0.0;
  double sensor_noise = 0.0;
  // Encoder settings; its fps is replaced by `fps`. An interlaced encoder
  // (EncoderOptions::interlaced) is an interlaced camera: each frame's bottom
  // field (odd rows) is rendered half a frame after its top field (even rows),
  // as the sensor captures them; the ground truth's pose and labels are the
  // top field's (the frame's timestamp).
  EncoderOptions encoder;
  std::string output_dir;
  std::string video_name = "drive.ts";
};

struct SimulateReport {
  int frames = 0;
  double distance_m = 0.0;
  double render_s = 0.0;  // wall time rendering (including texture making)
  double encode_s = 0.0;  // wall time in the encoder
  int num_planes = 0;
  std::string video_path;
};

// Everything about a drive except its pixels: what SimulateDrive renders.
struct Drive {
  Scene scene;
  CameraPath path;
  Intrinsics intrinsics;
};

// Builds the scene (long enough for the path plus margin) and the path.
StatusOr<Drive> PrepareDrive(const SimulateOptions& options);

// Renders, encodes and writes a drive with its ground truth into options.output_dir.
Status SimulateDrive(const SimulateOptions& options, SimulateReport* report);

}  // namespace slapse
