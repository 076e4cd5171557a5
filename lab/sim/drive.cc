#include <cmath>
#include <string>

#include "core/common/mb_grid.h"
#include "lab/sim/random.h"
#include "lab/sim/simulate.h"

namespace slapse {

StatusOr<Drive> PrepareDrive(const SimulateOptions& o) {
  if (!(o.duration_s > 0 && o.duration_s <= 3600)) {
    return InvalidArgumentError("duration_s must be in (0, 3600]");
  }
  if (!(o.fps > 0 && o.fps <= 240)) return InvalidArgumentError("fps must be in (0, 240]");
  if (o.width_px < kMbSizePx || o.height_px < kMbSizePx || o.width_px > 4096 ||
      o.height_px > 4096) {
    return InvalidArgumentError("frame size must be within 16..4096 pixels");
  }
  if (!(o.hfov_deg > 10 && o.hfov_deg < 150)) {
    return InvalidArgumentError("hfov_deg must be in (10, 150)");
  }
  if (!(o.camera_height_min_m >= 0.3 && o.camera_height_max_m <= 10.0) ||
      !(o.pitch_down_min_deg >= -30 && o.pitch_down_max_deg <= 30)) {
    return InvalidArgumentError(
        "camera height must be within 0.3..10 m and pitch within -30..30 deg");
  }
  if (!(o.bounce_m >= 0 && o.bounce_m <= 0.2 && o.bounce_m < o.camera_height_min_m)) {
    return InvalidArgumentError("bounce_m must be in [0, 0.2] m and below the camera height");
  }
  if (!(o.blur_px >= 0 && o.blur_px <= 5 && o.sensor_noise >= 0 && o.sensor_noise <= 50)) {
    return InvalidArgumentError("blur_px must be in [0, 5] and sensor_noise in [0, 50]");
  }
  Drive drive;
  drive.intrinsics = Intrinsics::FromHorizontalFov(o.width_px, o.height_px, o.hfov_deg);

  PathOptions path;
  path.seed = Mix64(o.seed ^ 0x0A11CE);
  path.fps = o.fps;
  path.num_frames = std::max(1, static_cast<int>(std::lround(o.duration_s * o.fps)));
  path.min_speed_mps = o.min_speed_mps;
  path.max_speed_mps = o.max_speed_mps;
  path.camera_height_min_m = o.camera_height_min_m;
  path.camera_height_max_m = o.camera_height_max_m;
  path.pitch_down_min_deg = o.pitch_down_min_deg;
  path.pitch_down_max_deg = o.pitch_down_max_deg;
  path.bounce_m = o.bounce_m;
  path.half_frame_poses = o.encoder.interlaced;  // the bottom fields' instants

  SceneOptions scene = SceneOptionsFor(o.scene_kind);
  scene.appearance_variety = o.appearance_variety;
  scene.seed = o.seed;
  scene.trees = o.trees;
  // Room for the longest possible path plus 50 m of street ahead of the last frame.
  scene.length_m = MaxPathLength(path) + 50.0;
  auto sc = GenerateStreetScene(scene);
  if (!sc.ok()) return sc.status();
  drive.scene = std::move(sc).value();
  auto p = GenerateCameraPath(drive.scene, path);
  if (!p.ok()) return p.status();
  drive.path = std::move(p).value();
  return drive;
}

}  // namespace slapse
