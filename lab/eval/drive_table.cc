#include "lab/eval/drive_table.h"

#include <algorithm>

#include "lab/sim/random.h"

namespace slapse {

const char* DriveSplitName(DriveSplit split) {
  return split == DriveSplit::kTuning ? "tuning" : "reporting";
}

namespace {

struct SpeedRange {
  double min_kmh, max_kmh;
};
// Indexed by SceneKind.
constexpr SpeedRange kSpeeds[kNumSceneKinds] = {
    {25, 50},   // urban
    {20, 50},   // avenue
    {40, 90},   // rural
    {70, 100},  // highway
    {10, 20},   // plaza
    {15, 35},   // intersection
};
constexpr double kFps[4] = {10, 25, 30, 60};
struct Resolution {
  int width, height;
  double hfov_min_deg, hfov_max_deg;
};
constexpr Resolution kResolutions[3] = {
    {640, 480, 60, 75}, {1280, 720, 70, 90}, {1242, 376, 78, 88}};

}  // namespace

DriveSpec MakeDriveSpec(SceneKind kind, int seed) {
  const int k = static_cast<int>(kind);
  DriveSpec d;
  d.kind = kind;
  d.seed = seed;
  d.split = SplitOfSeed(seed);
  d.name = std::string(SceneKindName(kind)) + "-" + std::to_string(seed);
  SimulateOptions& o = d.sim;
  o.seed = static_cast<uint64_t>(1000 * (k + 1) + seed);
  o.scene_kind = kind;
  o.appearance_variety = true;
  // seed / 2 runs through 0..3 over the odd seeds 1, 3, 5, 7 and over the even
  // seeds 2, 4, 6, 8 (mod 4): both splits see every frame rate in each kind.
  o.fps = kFps[(seed / 2 + k) % 4];
  const Resolution& r = kResolutions[(seed + k) % 3];
  o.width_px = r.width;
  o.height_px = r.height;
  SimRandom rng(Mix64(o.seed ^ 0xD417E5ULL));
  o.hfov_deg = rng.Uniform(r.hfov_min_deg, r.hfov_max_deg);
  o.camera_height_min_m = o.camera_height_max_m = rng.Uniform(1.2, 2.5);
  o.pitch_down_min_deg = o.pitch_down_max_deg = -rng.Uniform(-10.0, 5.0);
  o.min_speed_mps = kSpeeds[k].min_kmh / 3.6;
  o.max_speed_mps = kSpeeds[k].max_kmh / 3.6;
  // 5 s (4 s at 60 fps): 50-240 frames.
  o.duration_s = o.fps >= 60 ? 4.0 : 5.0;
  // Anti-aliasing: 1-3 samples per pixel and axis (at most 2 above 640x480).
  o.supersampling = std::min(1 + (seed + 2 * k) % 3, r.width > 640 ? 2 : 3);
  o.blur_px = rng.Bernoulli(0.5) ? rng.Uniform(0.3, 0.8) : 0.0;
  o.sensor_noise = rng.Uniform(0.0, 2.5);
  // The body's bounce on its suspension: from a smooth highway to a rough lane.
  o.bounce_m = rng.Uniform(0.005, 0.03);
  return d;
}

std::vector<DriveSpec> DriveTable(int seeds_per_kind) {
  std::vector<DriveSpec> table;
  for (int k = 0; k < kNumSceneKinds; ++k) {
    for (int seed = 1; seed <= seeds_per_kind; ++seed) {
      table.push_back(MakeDriveSpec(static_cast<SceneKind>(k), seed));
    }
  }
  return table;
}

StatusOr<DriveSpec> ParseDriveName(const std::string& name) {
  const size_t dash = name.rfind('-');
  if (dash == std::string::npos || dash + 1 >= name.size()) {
    return InvalidArgumentError("drive name must look like KIND-SEED (e.g. rural-3), got '" + name +
                                "'");
  }
  auto kind = ParseSceneKind(name.substr(0, dash));
  if (!kind.ok()) return kind.status();
  const std::string digits = name.substr(dash + 1);
  if (digits.size() > 6 || digits.find_first_not_of("0123456789") != std::string::npos ||
      std::stoi(digits) < 1) {
    return InvalidArgumentError("drive seed must be a number >= 1, got '" + digits + "'");
  }
  return MakeDriveSpec(*kind, std::stoi(digits));
}

namespace {
const char* const kYardstickProfiles[] = {"mpeg2-ibbbp", "mpeg4-ibbbp", "h264-ibbbp", "h264-ippp"};
}  // namespace

std::vector<std::string> EncoderProfileNames() {
  std::vector<std::string> names(std::begin(kYardstickProfiles), std::end(kYardstickProfiles));
  for (const std::string& n : EncoderPresetNames()) {
    if (std::find(names.begin(), names.end(), n) == names.end()) names.push_back(n);
  }
  return names;
}

StatusOr<EncoderOptions> EncoderProfile(const std::string& name, double fps) {
  if (std::find(std::begin(kYardstickProfiles), std::end(kYardstickProfiles), name) ==
      std::end(kYardstickProfiles)) {
    const auto names = EncoderPresetNames();
    if (std::find(names.begin(), names.end(), name) != names.end()) {
      return EncoderPreset(name, fps);
    }
  }
  EncoderOptions e;
  e.gop_size = 12;
  if (name == "mpeg2-ibbbp") {
    e.codec = VideoCodec::kMpeg2;
    e.b_frames = 3;
    e.quality = 4;
  } else if (name == "mpeg4-ibbbp") {
    e.codec = VideoCodec::kMpeg4;
    e.b_frames = 3;
    e.quality = 4;
  } else if (name == "h264-ibbbp" || name == "h264-ippp") {
    e.codec = VideoCodec::kH264;
    e.b_frames = name == "h264-ibbbp" ? 3 : 0;
    e.quality = 20;
  } else {
    std::string known;
    for (const auto& n : EncoderProfileNames()) known += (known.empty() ? "" : ", ") + n;
    return InvalidArgumentError("unknown encoder profile '" + name + "' (known: " + known + ")");
  }
  return e;
}

}  // namespace slapse
