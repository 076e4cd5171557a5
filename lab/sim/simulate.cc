#include "lab/sim/simulate.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <opencv2/imgproc.hpp>

#include "core/common/json_io.h"
#include "core/common/timing.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/random.h"

namespace slapse {

namespace {

using Clock = std::chrono::steady_clock;

// The full meta.json (a superset of what SaveGroundTruth wrote).
Status WriteMeta(const SimulateOptions& o, const EncoderOptions& eo, const Drive& drive,
                 const GroundTruth& gt, const SimulateReport& report) {
  Json meta;
  meta["seed"] = o.seed;
  meta["video"] = o.video_name;
  meta["codec"] = VideoCodecName(eo.codec);
  meta["b_frames"] = eo.b_frames;
  meta["gop_size"] = eo.gop_size;
  meta["quality"] = eo.quality;
  meta["mpeg4_qpel"] = eo.mpeg4_qpel;
  meta["interlaced"] = eo.interlaced;
  if (eo.h264_x264_defaults) meta["h264_x264_defaults"] = true;  // b_frames, gop_size unused
  meta["fps"] = o.fps;
  meta["frames"] = gt.frames.size();
  meta["width_px"] = o.width_px;
  meta["height_px"] = o.height_px;
  meta["hfov_deg"] = o.hfov_deg;
  meta["mb_cols"] = gt.mb_cols;
  meta["mb_rows"] = gt.mb_rows;
  meta["duration_s"] = o.duration_s;
  meta["min_speed_mps"] = o.min_speed_mps;
  meta["max_speed_mps"] = o.max_speed_mps;
  meta["trees"] = o.trees;
  meta["scene_kind"] = SceneKindName(o.scene_kind);
  meta["appearance_variety"] = o.appearance_variety;
  meta["blur_px"] = o.blur_px;
  meta["sensor_noise"] = o.sensor_noise;
  meta["supersampling"] = o.supersampling;
  meta["camera_height_m"] = drive.path.camera_height_m;
  meta["pitch_down_deg"] = drive.path.pitch_down_deg;
  meta["bounce_m"] = o.bounce_m;
  meta["distance_m"] = drive.path.distance_m;
  meta["num_planes"] = drive.scene.planes.size();
  meta["render_s"] = report.render_s;
  meta["encode_s"] = report.encode_s;
  const auto meta_path = std::filesystem::path(o.output_dir) / "meta.json";
  std::ofstream out(meta_path, std::ios::trunc);
  out << DumpJson(meta, ExactNumber);
  out.close();
  if (!out) return DataLossError("failed writing " + meta_path.string());
  return Status::Ok();
}

// Blur and sensor noise (SimulateOptions::blur_px, sensor_noise) on a rendered frame.
void ApplyCameraOptics(const SimulateOptions& o, size_t frame, cv::Mat* bgr) {
  if (o.blur_px > 0) cv::GaussianBlur(*bgr, *bgr, cv::Size(0, 0), o.blur_px);
  if (o.sensor_noise > 0) {
    cv::Mat noise(bgr->size(), CV_16SC3);
    cv::RNG rng(Mix64(o.seed ^ (0x5E45ULL + frame)));
    rng.fill(noise, cv::RNG::NORMAL, 0.0, o.sensor_noise);
    cv::Mat sum;
    cv::add(*bgr, noise, sum, cv::noArray(), CV_16SC3);
    sum.convertTo(*bgr, CV_8UC3);
  }
}

// An interlaced camera's frame: the odd rows (bottom field) of `bottom_field`
// over `frame`'s even rows (top field).
void WeaveBottomField(const cv::Mat& bottom_field, cv::Mat* frame) {
  for (int r = 1; r < frame->rows; r += 2) bottom_field.row(r).copyTo(frame->row(r));
}

}  // namespace

Status SimulateDrive(const SimulateOptions& o, SimulateReport* report) {
  if (report == nullptr) return InvalidArgumentError("SimulateDrive: null report");
  if (o.output_dir.empty()) return InvalidArgumentError("SimulateDrive: empty output_dir");
  if (o.video_name.empty() || o.video_name.find('/') != std::string::npos) {
    return InvalidArgumentError("video_name must be a plain file name");
  }
  *report = SimulateReport();
  auto drive_or = PrepareDrive(o);
  if (!drive_or.ok()) return drive_or.status();
  const Drive& drive = *drive_or;

  std::error_code ec;
  std::filesystem::create_directories(o.output_dir, ec);
  if (ec) return UnavailableError("cannot create " + o.output_dir + ": " + ec.message());
  const std::string video_path = (std::filesystem::path(o.output_dir) / o.video_name).string();

  RenderOptions ro;
  ro.supersampling = o.supersampling;
  ro.sky_horizon_bgr = drive.scene.lighting.sky_horizon_bgr;
  ro.sky_zenith_bgr = drive.scene.lighting.sky_zenith_bgr;
  auto renderer_or = Renderer::Create(drive.scene, drive.intrinsics, ro);
  if (!renderer_or.ok()) return renderer_or.status();
  Renderer& renderer = **renderer_or;

  EncoderOptions eo = o.encoder;
  eo.fps = o.fps;
  auto encoder_or = VideoEncoder::Open(video_path, o.width_px, o.height_px, eo);
  if (!encoder_or.ok()) return encoder_or.status();
  VideoEncoder& encoder = **encoder_or;

  GroundTruth gt;
  gt.intrinsics = drive.intrinsics;
  gt.planes = drive.scene.planes;
  gt.fps = o.fps;
  RenderedFrame frame, bottom_field;
  const size_t n = drive.path.world_from_cam.size();
  const bool interlaced = !drive.path.half_frame_world_from_cam.empty();
  for (size_t i = 0; i < n; ++i) {
    const auto t0 = Clock::now();
    SLAPSE_RETURN_IF_ERROR(renderer.Render(drive.path.world_from_cam[i], &frame));
    if (interlaced) {
      SLAPSE_RETURN_IF_ERROR(
          renderer.Render(drive.path.half_frame_world_from_cam[i], &bottom_field));
      WeaveBottomField(bottom_field.bgr, &frame.bgr);
    }
    ApplyCameraOptics(o, i, &frame.bgr);
    const auto t1 = Clock::now();
    SLAPSE_RETURN_IF_ERROR(encoder.Write(frame.bgr));
    const auto t2 = Clock::now();
    report->render_s += SecondsBetween(t0, t1);
    report->encode_s += SecondsBetween(t1, t2);
    GtFrame f;
    f.timestamp_s = drive.path.timestamps_s[i];
    f.world_from_cam = drive.path.world_from_cam[i];
    f.mb_labels = frame.mb_labels;
    f.mixed_shares = frame.mb_mixed_shares;
    gt.mb_cols = frame.mb_cols;
    gt.mb_rows = frame.mb_rows;
    gt.frames.push_back(std::move(f));
  }
  const auto t3 = Clock::now();
  SLAPSE_RETURN_IF_ERROR(encoder.Finish());
  report->encode_s += SecondsBetween(t3, Clock::now());
  SLAPSE_RETURN_IF_ERROR(SaveGroundTruth(gt, o.output_dir));

  report->frames = static_cast<int>(n);
  report->distance_m = drive.path.distance_m;
  report->num_planes = static_cast<int>(drive.scene.planes.size());
  report->video_path = video_path;

  return WriteMeta(o, eo, drive, gt, *report);
}

}  // namespace slapse
