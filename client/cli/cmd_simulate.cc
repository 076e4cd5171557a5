// slapse simulate: render a textured street drive with a known camera path,
// encode it with a real encoder, and write the ground truth beside it.
#include <cstdio>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "core/sim/simulate.h"

namespace slapse::cli {
namespace {

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

}  // namespace

int RunSimulate(int argc, char** argv) {
  Flags flags(
      "simulate", "--out DIR [options]",
      {{"out", "DIR", "output directory (created)", ""},
       {"seed", "N", "scene and path seed", "1"},
       {"codec", "NAME", "mpeg2, mpeg4 or h264", "mpeg2"},
       {"gop", "PATTERN", "IBBBP (n_B = 3), IBBP, IPPP ...", "IBBBP"},
       {"gop-size", "N", "frames from one I frame to the next", "12"},
       {"quality", "Q", "MPEG quantiser 1..31, or H.264 CRF 0..51", "4 (MPEG), 20 (H.264)"},
       {"duration-s", "S", "length of the drive in seconds", "10"},
       {"fps", "F", "frame rate", "30"},
       {"width", "PX", "frame width", "640"},
       {"height", "PX", "frame height", "480"},
       {"hfov-deg", "DEG", "horizontal field of view", "70"},
       {"min-speed-kmh", "V", "slowest speed of the car", "25"},
       {"max-speed-kmh", "V", "fastest speed of the car", "50"},
       {"no-trees", "", "leave out the non-planar clutter", ""},
       {"video-name", "FILE", "video file name; its extension picks the container", "drive.ts"}});
  if (Status s = flags.Parse(argc, argv); !s.ok()) return Fail("simulate", s.message(), 2);
  if (flags.help_requested()) {
    std::printf("%s", flags.Usage().c_str());
    return 0;
  }
  if (!flags.positional().empty()) {
    return Fail("simulate", "unexpected argument '" + flags.positional()[0] + "'", 2);
  }
  if (!flags.Has("out")) return Fail("simulate", "--out DIR is required (see --help)", 2);

  SimulateOptions opt;
  opt.output_dir = flags.GetString("out");
  opt.video_name = flags.GetString("video-name");
  opt.trees = !flags.GetBool("no-trees");
  auto codec = ParseVideoCodec(flags.GetString("codec"));
  auto b_frames = ParseGopPattern(flags.GetString("gop"));
  auto seed = flags.GetInt("seed", 0, INT64_MAX);
  auto gop_size = flags.GetInt("gop-size", 1, 600);
  auto duration = flags.GetDouble("duration-s", 0.2, 600);
  auto fps = flags.GetDouble("fps", 1, 120);
  auto width = flags.GetInt("width", 64, 4096);
  auto height = flags.GetInt("height", 64, 4096);
  auto hfov = flags.GetDouble("hfov-deg", 20, 150);
  auto vmin = flags.GetDouble("min-speed-kmh", 1, 200);
  auto vmax = flags.GetDouble("max-speed-kmh", 1, 200);
  for (const Status* s : {&codec.status(), &b_frames.status(), &seed.status(), &gop_size.status(),
                          &duration.status(), &fps.status(), &width.status(), &height.status(),
                          &hfov.status(), &vmin.status(), &vmax.status()}) {
    if (!s->ok()) return Fail("simulate", s->message(), 2);
  }
  if (*vmin > *vmax) return Fail("simulate", "--min-speed-kmh exceeds --max-speed-kmh", 2);
  if (*width % 2 || *height % 2) return Fail("simulate", "--width and --height must be even", 2);
  opt.seed = static_cast<uint64_t>(*seed);
  opt.duration_s = *duration;
  opt.fps = *fps;
  opt.width_px = static_cast<int>(*width);
  opt.height_px = static_cast<int>(*height);
  opt.hfov_deg = *hfov;
  opt.min_speed_mps = *vmin / 3.6;
  opt.max_speed_mps = *vmax / 3.6;
  opt.encoder.codec = *codec;
  opt.encoder.b_frames = *b_frames;
  opt.encoder.gop_size = static_cast<int>(*gop_size);
  if (flags.Has("quality")) {
    auto q = flags.GetInt("quality", 0, 51);
    if (!q.ok()) return Fail("simulate", q.status().message(), 2);
    opt.encoder.quality = static_cast<int>(*q);
  } else {
    opt.encoder.quality = *codec == VideoCodec::kH264 ? 20 : 4;
  }

  SimulateReport report;
  if (Status s = SimulateDrive(opt, &report); !s.ok()) return Fail("simulate", s.ToString());
  std::printf("video      %s (%s, %s, %d frames, %dx%d @ %.0f fps)\n", report.video_path.c_str(),
              VideoCodecName(opt.encoder.codec), flags.GetString("gop").c_str(), report.frames,
              opt.width_px, opt.height_px, opt.fps);
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
