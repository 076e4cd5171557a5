// slapse simulate: render a textured street drive with a known camera path,
// encode it with a real encoder, and write the ground truth beside it.
#include <cstdio>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "lab/sim/simulate.h"

namespace slapse::cli {
namespace {

// H.264's CRF when --quality is not given (MPEG codecs use EncoderOptions{}.quality).
constexpr int kH264Quality = 20;

// "IBBBP" -> 3 B frames, "IPPP" / "IP" -> 0.
StatusOr<int> ParseGopPattern(const std::string& gop) {
  if (gop.size() < 2 || gop[0] != 'I' || gop.back() != 'P') {
    return InvalidArgumentError("--gop must look like IBBBP, IBBP or IPPP, got '" + gop + "'");
  }
  const std::string middle = gop.substr(1, gop.size() - 2);
  if (middle.find_first_not_of('B') == std::string::npos) return static_cast<int>(middle.size());
  if (middle.find_first_not_of('P') == std::string::npos) return 0;
  return InvalidArgumentError("--gop must look like IBBBP, IBBP or IPPP, got '" + gop + "'");
}

// simulate's flags, bound to a SimulateOptions (defaults: SimulateOptions{}).
struct SimulateFlags {
  SimulateOptions opt;
  std::string codec_name = VideoCodecName(opt.encoder.codec), gop = "IBBBP";
  int64_t seed = static_cast<int64_t>(opt.seed), gop_size = opt.encoder.gop_size;
  int64_t width = opt.width_px, height = opt.height_px, quality = opt.encoder.quality;
  // km/h on the command line, m/s in SimulateOptions: converted only when given,
  // so the defaults stay SimulateOptions{}'s exact values.
  double min_kmh = opt.min_speed_mps * 3.6, max_kmh = opt.max_speed_mps * 3.6;
  bool no_trees = false;
  std::string preset;
  std::string scene_kind = SceneKindName(opt.scene_kind);
  double camera_height_m = 0.0, pitch_deg = 0.0;  // 0 / unset: the path's default ranges
  int64_t supersampling = opt.supersampling;

  void AddTo(CLI::App& app) {
    std::string names;
    for (const std::string& n : EncoderPresetNames()) names += (names.empty() ? "" : ", ") + n;
    app.add_option("--preset", preset,
                   "camera-like encoder settings instead of --codec/--gop (" + names +
                       "); --gop-size and --quality still override")
        ->type_name("NAME");
    app.add_option("--out", opt.output_dir, "output directory (created)")->type_name("DIR");
    app.add_option("--seed", seed, "scene and path seed")->type_name("N")->capture_default_str();
    app.add_option("--codec", codec_name, "mpeg2, mpeg4, h264, hevc, vp9 or mjpeg")
        ->type_name("NAME")
        ->capture_default_str();
    app.add_option("--gop", gop, "IBBBP (n_B = 3), IBBP, IPPP ...")
        ->type_name("PATTERN")
        ->capture_default_str();
    app.add_option("--gop-size", gop_size, "frames from one I frame to the next")
        ->type_name("N")
        ->capture_default_str();
    app.add_option("--quality", quality, "MPEG quantiser 1..31, or H.264 CRF 0..51")
        ->type_name("Q")
        ->default_str(std::to_string(quality) + " (MPEG), " + std::to_string(kH264Quality) +
                      " (H.264)");
    app.add_option("--duration-s", opt.duration_s, "length of the drive in seconds")
        ->type_name("S")
        ->capture_default_str();
    app.add_option("--fps", opt.fps, "frame rate")->type_name("F")->capture_default_str();
    app.add_option("--width", width, "frame width")->type_name("PX")->capture_default_str();
    app.add_option("--height", height, "frame height")->type_name("PX")->capture_default_str();
    app.add_option("--hfov-deg", opt.hfov_deg, "horizontal field of view")
        ->type_name("DEG")
        ->capture_default_str();
    app.add_option("--min-speed-kmh", min_kmh, "slowest speed of the car")
        ->type_name("V")
        ->capture_default_str();
    app.add_option("--max-speed-kmh", max_kmh, "fastest speed of the car")
        ->type_name("V")
        ->capture_default_str();
    app.add_flag("--no-trees", no_trees, "leave out the non-planar clutter");
    app.add_option("--scene-kind", scene_kind,
                   "urban, avenue, rural, highway, plaza or intersection (lab/sim/scene.h)")
        ->type_name("KIND")
        ->capture_default_str();
    app.add_flag("--vary-look", opt.appearance_variety,
                 "vary road appearance, markings, light and sky with the seed");
    app.add_option("--camera-height-m", camera_height_m,
                   "camera height above the road (default: drawn from 1.3-1.6 m)")
        ->type_name("M");
    app.add_option("--pitch-deg", pitch_deg,
                   "fixed camera pitch, up positive (default: drawn from -5..-2 deg)")
        ->type_name("DEG");
    app.add_option("--bounce-m", opt.bounce_m,
                   "peak vertical bounce of the camera on the car's suspension")
        ->type_name("M")
        ->capture_default_str();
    app.add_option("--supersampling", supersampling, "anti-aliasing samples per pixel and axis")
        ->type_name("N")
        ->capture_default_str();
    app.add_option("--blur-px", opt.blur_px, "Gaussian blur of each frame (sigma, pixels)")
        ->type_name("PX")
        ->capture_default_str();
    app.add_option("--sensor-noise", opt.sensor_noise,
                   "Gaussian sensor noise (sigma, 8-bit levels)")
        ->type_name("SIGMA")
        ->capture_default_str();
    app.add_option("--video-name", opt.video_name,
                   "video file name; its extension picks the container")
        ->type_name("FILE")
        ->capture_default_str();
  }

  // Range checks; fills `opt` (usage errors as INVALID_ARGUMENT).
  Status Apply(const CommandLine& cl);
};

Status SimulateFlags::Apply(const CommandLine& cl) {
  opt.trees = !no_trees;
  auto codec = ParseVideoCodec(codec_name);
  auto b_frames = ParseGopPattern(gop);
  for (const Status& s :
       {codec.status(), b_frames.status(), CheckRange("seed", seed, int64_t{0}, INT64_MAX),
        CheckRange("gop-size", gop_size, int64_t{1}, int64_t{600}),
        CheckRange("duration-s", opt.duration_s, 0.2, 600), CheckRange("fps", opt.fps, 1, 120),
        CheckRange("width", width, int64_t{64}, int64_t{4096}),
        CheckRange("height", height, int64_t{64}, int64_t{4096}),
        CheckRange("hfov-deg", opt.hfov_deg, 20, 150), CheckRange("min-speed-kmh", min_kmh, 1, 200),
        CheckRange("max-speed-kmh", max_kmh, 1, 200)}) {
    if (!s.ok()) return s;
  }
  auto kind = ParseSceneKind(scene_kind);
  if (!kind.ok()) return kind.status();
  opt.scene_kind = *kind;
  for (const Status& s :
       {CheckRange("supersampling", supersampling, int64_t{1}, int64_t{4}),
        CheckRange("blur-px", opt.blur_px, 0, 5), CheckRange("bounce-m", opt.bounce_m, 0, 0.2),
        CheckRange("sensor-noise", opt.sensor_noise, 0, 50),
        cl.Has("camera-height-m") ? CheckRange("camera-height-m", camera_height_m, 0.3, 10)
                                  : Status::Ok(),
        cl.Has("pitch-deg") ? CheckRange("pitch-deg", pitch_deg, -30, 30) : Status::Ok()}) {
    if (!s.ok()) return s;
  }
  opt.supersampling = static_cast<int>(supersampling);
  if (cl.Has("camera-height-m"))
    opt.camera_height_min_m = opt.camera_height_max_m = camera_height_m;
  if (cl.Has("pitch-deg")) opt.pitch_down_min_deg = opt.pitch_down_max_deg = -pitch_deg;
  if (cl.Has("min-speed-kmh")) opt.min_speed_mps = min_kmh / 3.6;
  if (cl.Has("max-speed-kmh")) opt.max_speed_mps = max_kmh / 3.6;
  if (opt.min_speed_mps > opt.max_speed_mps) {
    return InvalidArgumentError("--min-speed-kmh exceeds --max-speed-kmh");
  }
  if (width % 2 || height % 2) return InvalidArgumentError("--width and --height must be even");
  opt.seed = static_cast<uint64_t>(seed);
  opt.width_px = static_cast<int>(width);
  opt.height_px = static_cast<int>(height);
  if (cl.Has("preset")) {
    if (cl.Has("codec") || cl.Has("gop")) {
      return InvalidArgumentError("--preset sets the codec and GOP: leave out --codec and --gop");
    }
    auto p = EncoderPreset(preset, opt.fps);
    if (!p.ok()) return p.status();
    opt.encoder = *p;
    if (cl.Has("gop-size")) opt.encoder.gop_size = static_cast<int>(gop_size);
    if (cl.Has("quality")) {
      SLAPSE_RETURN_IF_ERROR(CheckRange("quality", quality, int64_t{0}, int64_t{51}));
      opt.encoder.quality = static_cast<int>(quality);
    }
    // MPEG-TS carries no MJPEG.
    if (opt.encoder.codec == VideoCodec::kMjpeg && !cl.Has("video-name")) {
      opt.video_name = "drive.mkv";
    }
    return Status::Ok();
  }
  opt.encoder.codec = *codec;
  opt.encoder.b_frames = *b_frames;
  opt.encoder.gop_size = static_cast<int>(gop_size);
  if (cl.Has("quality")) {
    SLAPSE_RETURN_IF_ERROR(CheckRange("quality", quality, int64_t{0}, int64_t{51}));
    opt.encoder.quality = static_cast<int>(quality);
  } else if (*codec == VideoCodec::kH264) {
    opt.encoder.quality = kH264Quality;
  }

  return Status::Ok();
}

}  // namespace

int RunSimulate(int argc, char** argv) {
  CommandLine cl("simulate", "--out DIR [options]");
  SimulateFlags flags;
  flags.AddTo(cl.app());
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (!cl.positional().empty()) {
    return Fail("simulate", "unexpected argument '" + cl.positional()[0] + "'", 2);
  }
  if (!cl.Has("out")) return Fail("simulate", "--out DIR is required (see --help)", 2);
  if (Status s = flags.Apply(cl); !s.ok()) return Fail("simulate", s.message(), 2);
  const SimulateOptions& opt = flags.opt;
  const std::string& gop = cl.Has("preset") ? flags.preset : flags.gop;

  SimulateReport report;
  if (Status s = SimulateDrive(opt, &report); !s.ok()) return Fail("simulate", s.ToString());
  std::printf("video      %s (%s, %s, %d frames, %dx%d @ %.0f fps)\n", report.video_path.c_str(),
              VideoCodecName(opt.encoder.codec), gop.c_str(), report.frames, opt.width_px,
              opt.height_px, opt.fps);
  std::printf("drive      %.1f m, %d planes in the scene, seed %llu\n", report.distance_m,
              report.num_planes, static_cast<unsigned long long>(opt.seed));
  std::printf("time       render %.2f s (%.1f ms/frame), encode %.2f s (%.1f ms/frame)\n",
              report.render_s, 1e3 * report.render_s / std::max(report.frames, 1), report.encode_s,
              1e3 * report.encode_s / std::max(report.frames, 1));
  std::printf(
      "truth      %s/{trajectory_tum.txt, intrinsics.json, planes.json, mb_labels.txt, "
      "mb_mixed.txt, meta.json}\n",
      opt.output_dir.c_str());
  return 0;
}

}  // namespace slapse::cli
