// slapse mvs: read a stream's motion vectors; dump them as CSV or JSON lines,
// draw them over a decoded frame, and print a summary of the stream.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>

#include <opencv2/imgcodecs.hpp>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "core/common/json_io.h"
#include "core/mv/mv_reader.h"
#include "core/viz/mv_overlay.h"

namespace slapse::cli {
namespace {

// Opens `path` for writing, "-" meaning stdout.
class Output {
 public:
  bool Open(const std::string& path) {
    if (path == "-") {
      out_ = &std::cout;
      return true;
    }
    file_ = std::make_unique<std::ofstream>(path);
    out_ = file_.get();
    return file_->good();
  }
  std::ostream* get() { return out_; }

 private:
  std::unique_ptr<std::ofstream> file_;
  std::ostream* out_ = nullptr;
};

void WriteCsv(std::ostream& os, const FrameRecord& f) {
  char line[160];
  for (const MotionVector& mv : f.mvs) {
    std::snprintf(line, sizeof(line), "%lld,%.6f,%c,%s,%.1f,%.1f,%.3f,%.3f,%d,%d\n",
                  static_cast<long long>(f.index), f.timestamp_s, PictureTypeChar(f.type),
                  mv.direction == RefDirection::kPast ? "past" : "future", mv.x_px, mv.y_px,
                  mv.dx_px, mv.dy_px, mv.w_px, mv.h_px);
    os << line;
  }
}

// The numbers of --json: the timestamp to the microsecond; each MV as
// [x_px, y_px, dx_px, dy_px, w_px, h_px, direction], positions to 0.1 px and
// displacements to 0.001 px (the sizes and direction are integers).
std::string MvsJsonNumber(const std::string& key, size_t index, double v) {
  if (key == "mvs") return FormatDouble(index < 2 ? "%.1f" : "%.3f", v);
  return FormatDouble("%.6f", v);
}

void WriteJsonLine(std::ostream& os, const FrameRecord& f) {
  Json line;
  line["index"] = static_cast<long long>(f.index);
  line["timestamp_s"] = f.timestamp_s;
  line["type"] = std::string(1, PictureTypeChar(f.type));
  line["prev_anchor"] = static_cast<long long>(f.prev_anchor_index);
  line["next_anchor"] = static_cast<long long>(f.next_anchor_index);
  line["corrupt"] = f.corrupt;
  Json& mvs = line["mvs"] = Json::array();
  for (const MotionVector& mv : f.mvs) {
    mvs.push_back({static_cast<double>(mv.x_px), static_cast<double>(mv.y_px),
                   static_cast<double>(mv.dx_px), static_cast<double>(mv.dy_px), mv.w_px, mv.h_px,
                   static_cast<int>(mv.direction)});
  }
  os << DumpJsonLine(line, MvsJsonNumber) << "\n";
}

double Median(std::vector<double>& v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// What the summary counts over the stream.
struct MvCounts {
  std::map<PictureType, int64_t> type_count;
  int64_t past = 0, future = 0;
  std::vector<double> p_motion, b_motion;  // |MV| by the frame type

  void Add(const FrameRecord& f) {
    ++type_count[f.type];
    for (const MotionVector& mv : f.mvs) {
      (mv.direction == RefDirection::kPast ? past : future)++;
      (f.type == PictureType::kP ? p_motion : b_motion).push_back(std::hypot(mv.dx_px, mv.dy_px));
    }
  }
};

void PrintSummary(const std::string& input, const StreamInfo& info, const ReadStats& stats,
                  MvCounts& c, double seconds) {
  std::printf("input      %s (%s, %s, %dx%d @ %.2f fps)\n", input.c_str(), info.format_name.c_str(),
              info.codec_name.c_str(), info.width_px, info.height_px, info.fps);
  std::printf(
      "frames     %lld (I %lld, P %lld, B %lld), n_B = %d, MV precision 1/%d px "
      "(sigma %.3f px)%s\n",
      static_cast<long long>(stats.frames), static_cast<long long>(c.type_count[PictureType::kI]),
      static_cast<long long>(c.type_count[PictureType::kP]),
      static_cast<long long>(c.type_count[PictureType::kB]), info.max_consecutive_b,
      info.mv_precision_denom, info.mv_sigma_px(),
      info.b_frame_mvs ? "" : ", B-frame MVs not exported by this decoder");
  if (info.b_pyramid || info.extra_references()) {
    std::printf(
        "references %s%s%s: FFmpeg does not say which reference a vector uses; slapse "
        "merges %s\n",
        info.b_pyramid ? "B-pyramid (B frames are references)" : "",
        info.b_pyramid && info.extra_references() ? ", " : "",
        info.extra_references()
            ? ("up to " + std::to_string(info.max_ref_frames) + " reference frames").c_str()
            : "",
        info.b_pyramid ? "direct vectors only" : "vectors as if they used the nearest anchor");
  }
  std::printf("vectors    %lld (past %lld, future %lld)\n",
              static_cast<long long>(c.past + c.future), static_cast<long long>(c.past),
              static_cast<long long>(c.future));
  std::printf("|motion|   median %.2f px in P frames, %.2f px in B frames\n", Median(c.p_motion),
              Median(c.b_motion));
  std::printf("speed      %.3f s, %.0f frames/s (open + demux + decode + MV export)\n", seconds,
              stats.frames / std::max(seconds, 1e-9));
}

}  // namespace

int RunMvs(int argc, char** argv) {
  CommandLine cl("mvs", "INPUT [options]   (INPUT: a file path or URL)", "INPUT");
  CLI::App& app = cl.app();
  std::string csv_path, json_path, png = "mv_overlay.png";
  int64_t draw_frame = -1;
  MvOverlayOptions overlay;
  MvReaderOptions options;
  bool quiet = false;
  app.add_option("--csv", csv_path, "write every MV as CSV ('-' = stdout)")->type_name("FILE");
  app.add_option("--json", json_path, "write one JSON object per frame ('-' = stdout)")
      ->type_name("FILE");
  app.add_option("--draw", draw_frame, "draw the MVs of this display-order frame over it")
      ->type_name("FRAME");
  app.add_option("--png", png, "where --draw writes its picture")
      ->type_name("FILE")
      ->capture_default_str();
  app.add_option("--arrow-scale", overlay.arrow_scale,
                 "arrow length per pixel of motion in the picture")
      ->type_name("X")
      ->capture_default_str();
  app.add_option("--format", options.format, "force the input format (mpegts, h264, ...)")
      ->type_name("NAME");
  app.add_flag("--quiet", quiet, "do not print the summary");
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (cl.positional().size() != 1) return Fail("mvs", "expected one INPUT (see --help)", 2);
  const std::string input = cl.positional()[0];
  if (cl.Has("draw")) {
    if (Status s = CheckRange("draw", draw_frame, int64_t{0}, INT64_MAX); !s.ok()) {
      return Fail("mvs", s.message(), 2);
    }
  }
  if (Status s = CheckRange("arrow-scale", overlay.arrow_scale, 0.1, 100.0); !s.ok()) {
    return Fail("mvs", s.message(), 2);
  }

  Output csv, json;
  if (cl.Has("csv")) {
    if (!csv.Open(csv_path)) return Fail("mvs", "cannot write " + csv_path);
    *csv.get() << "frame,timestamp_s,type,direction,x_px,y_px,dx_px,dy_px,w_px,h_px\n";
  }
  if (cl.Has("json") && !json.Open(json_path)) {
    return Fail("mvs", "cannot write " + json_path);
  }

  options.keep_luma = draw_frame >= 0;
  const auto t0 = std::chrono::steady_clock::now();
  auto reader = MvReader::Open(input, options);
  if (!reader.ok()) return Fail("mvs", reader.status().ToString());

  MvCounts counts;
  bool drawn = false;
  FrameRecord f;
  Status end;
  while ((end = (*reader)->Next(&f)).ok()) {
    counts.Add(f);
    if (csv.get() != nullptr) WriteCsv(*csv.get(), f);
    if (json.get() != nullptr) WriteJsonLine(*json.get(), f);
    if (f.index == draw_frame) {
      const cv::Mat picture =
          DrawMotionVectors(f, (*reader)->info().width_px, (*reader)->info().height_px, overlay);
      if (!cv::imwrite(png, picture)) {
        return Fail("mvs", "cannot write " + png);
      }
      drawn = true;
      options.keep_luma = false;
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const StreamInfo& info = (*reader)->info();
  const ReadStats& stats = (*reader)->stats();
  if (!quiet) {
    PrintSummary(input, info, stats, counts, seconds);
    if (drawn)
      std::printf("picture    %s (frame %lld)\n", png.c_str(), static_cast<long long>(draw_frame));
  }
  if (draw_frame >= 0 && !drawn) {
    return Fail("mvs", "--draw " + std::to_string(draw_frame) + ": the stream has only " +
                           std::to_string(stats.frames) + " frames");
  }
  if (end.code() != StatusCode::kOutOfRange) return Fail("mvs", end.ToString());
  return 0;
}

}  // namespace slapse::cli
