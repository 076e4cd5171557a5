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

void WriteJsonLine(std::ostream& os, const FrameRecord& f) {
  char head[200];
  std::snprintf(head, sizeof(head),
                "{\"index\":%lld,\"timestamp_s\":%.6f,\"type\":\"%c\",\"prev_anchor\":%lld,"
                "\"next_anchor\":%lld,\"corrupt\":%s,\"mvs\":[",
                static_cast<long long>(f.index), f.timestamp_s, PictureTypeChar(f.type),
                static_cast<long long>(f.prev_anchor_index),
                static_cast<long long>(f.next_anchor_index), f.corrupt ? "true" : "false");
  os << head;
  char item[120];
  for (size_t i = 0; i < f.mvs.size(); ++i) {
    const MotionVector& mv = f.mvs[i];
    std::snprintf(item, sizeof(item), "%s[%.1f,%.1f,%.3f,%.3f,%d,%d,%d]", i ? "," : "", mv.x_px,
                  mv.y_px, mv.dx_px, mv.dy_px, mv.w_px, mv.h_px, static_cast<int>(mv.direction));
    os << item;
  }
  os << "]}\n";
}

double Median(std::vector<double>& v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

int RunMvs(int argc, char** argv) {
  Flags flags("mvs", "INPUT [options]   (INPUT: a file path or URL)",
              {{"csv", "FILE", "write every MV as CSV ('-' = stdout)", ""},
               {"json", "FILE", "write one JSON object per frame ('-' = stdout)", ""},
               {"draw", "FRAME", "draw the MVs of this display-order frame over it", ""},
               {"png", "FILE", "where --draw writes its picture", "mv_overlay.png"},
               {"arrow-scale", "X", "arrow length per pixel of motion in the picture", "2"},
               {"format", "NAME", "force the input format (mpegts, h264, ...)", ""},
               {"quiet", "", "do not print the summary", ""}});
  if (Status s = flags.Parse(argc, argv); !s.ok()) return Fail("mvs", s.message(), 2);
  if (flags.help_requested()) {
    std::printf("%s", flags.Usage().c_str());
    return 0;
  }
  if (flags.positional().size() != 1) return Fail("mvs", "expected one INPUT (see --help)", 2);
  const std::string input = flags.positional()[0];
  int64_t draw_frame = -1;
  if (flags.Has("draw")) {
    auto v = flags.GetInt("draw", 0, INT64_MAX);
    if (!v.ok()) return Fail("mvs", v.status().message(), 2);
    draw_frame = *v;
  }
  auto arrow_scale = flags.GetDouble("arrow-scale", 0.1, 100.0);
  if (!arrow_scale.ok()) return Fail("mvs", arrow_scale.status().message(), 2);

  Output csv, json;
  if (flags.Has("csv")) {
    if (!csv.Open(flags.GetString("csv")))
      return Fail("mvs", "cannot write " + flags.GetString("csv"));
    *csv.get() << "frame,timestamp_s,type,direction,x_px,y_px,dx_px,dy_px,w_px,h_px\n";
  }
  if (flags.Has("json") && !json.Open(flags.GetString("json"))) {
    return Fail("mvs", "cannot write " + flags.GetString("json"));
  }

  MvReaderOptions options;
  options.format = flags.GetString("format");
  options.keep_luma = draw_frame >= 0;
  const auto t0 = std::chrono::steady_clock::now();
  auto reader = MvReader::Open(input, options);
  if (!reader.ok()) return Fail("mvs", reader.status().ToString());

  std::map<PictureType, int64_t> type_count;
  int64_t past = 0, future = 0;
  std::vector<double> p_motion, b_motion;
  bool drawn = false;
  FrameRecord f;
  Status end;
  while ((end = (*reader)->Next(&f)).ok()) {
    ++type_count[f.type];
    for (const MotionVector& mv : f.mvs) {
      (mv.direction == RefDirection::kPast ? past : future)++;
      (f.type == PictureType::kP ? p_motion : b_motion).push_back(std::hypot(mv.dx_px, mv.dy_px));
    }
    if (csv.get() != nullptr) WriteCsv(*csv.get(), f);
    if (json.get() != nullptr) WriteJsonLine(*json.get(), f);
    if (f.index == draw_frame) {
      MvOverlayOptions overlay;
      overlay.arrow_scale = *arrow_scale;
      const cv::Mat picture =
          DrawMotionVectors(f, (*reader)->info().width_px, (*reader)->info().height_px, overlay);
      if (!cv::imwrite(flags.GetString("png"), picture)) {
        return Fail("mvs", "cannot write " + flags.GetString("png"));
      }
      drawn = true;
      options.keep_luma = false;
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const StreamInfo& info = (*reader)->info();
  const ReadStats& stats = (*reader)->stats();
  if (!flags.GetBool("quiet")) {
    std::printf("input      %s (%s, %s, %dx%d @ %.2f fps)\n", input.c_str(),
                info.format_name.c_str(), info.codec_name.c_str(), info.width_px, info.height_px,
                info.fps);
    std::printf(
        "frames     %lld (I %lld, P %lld, B %lld), n_B = %d, MV precision 1/%d px "
        "(sigma %.3f px)%s\n",
        static_cast<long long>(stats.frames), static_cast<long long>(type_count[PictureType::kI]),
        static_cast<long long>(type_count[PictureType::kP]),
        static_cast<long long>(type_count[PictureType::kB]), info.max_consecutive_b,
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
    std::printf("vectors    %lld (past %lld, future %lld)\n", static_cast<long long>(past + future),
                static_cast<long long>(past), static_cast<long long>(future));
    std::printf("|motion|   median %.2f px in P frames, %.2f px in B frames\n", Median(p_motion),
                Median(b_motion));
    std::printf("speed      %.3f s, %.0f frames/s (open + demux + decode + MV export)\n", seconds,
                stats.frames / std::max(seconds, 1e-9));
    if (drawn)
      std::printf("picture    %s (frame %lld)\n", flags.GetString("png").c_str(),
                  static_cast<long long>(draw_frame));
  }
  if (draw_frame >= 0 && !drawn) {
    return Fail("mvs", "--draw " + std::to_string(draw_frame) + ": the stream has only " +
                           std::to_string(stats.frames) + " frames");
  }
  if (end.code() != StatusCode::kOutOfRange) return Fail("mvs", end.ToString());
  return 0;
}

}  // namespace slapse::cli
