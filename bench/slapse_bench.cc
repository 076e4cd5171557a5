// slapse_bench: what each stage costs, on a simulated drive or any stream.
//
//   build/bench/slapse_bench                    # simulates the default drive first
//   build/bench/slapse_bench --input FILE --repeat 5
//
// Prints a Markdown table: frames/s of bare FFmpeg decoding (no MV export),
// of the MV reader (decode + export_mvs + conversion), and of the whole SLAPSE
// pipeline (reader + merging + thresholding + plane fitting + EKF), the last
// two as shipped (MvReaderOptions::reduced_decode) and decoding every picture
// in full, each run in
// a fresh process of its own so that its peak memory is its own; then the
// pipeline's per-anchor-pair stage times. Timing lives here, never in tests.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/log.h>
}

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/simulate.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Result {
  double seconds = 0;
  long frames = 0;
  long peak_rss_kb = 0;
  double merge_ms = 0, threshold_ms = 0, fit_ms = 0, ekf_ms = 0, frame_poses_ms = 0, refine_ms = 0;
  long pairs = 0;
};

// Plain libavcodec decoding of every video frame, no side data: the floor.
long BareDecode(const std::string& path) {
  AVFormatContext* fmt = nullptr;
  if (avformat_open_input(&fmt, path.c_str(), nullptr, nullptr) < 0) return -1;
  avformat_find_stream_info(fmt, nullptr);
  const int si = av_find_best_stream(fmt, AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0);
  const AVCodec* codec = avcodec_find_decoder(fmt->streams[si]->codecpar->codec_id);
  AVCodecContext* dec = avcodec_alloc_context3(codec);
  avcodec_parameters_to_context(dec, fmt->streams[si]->codecpar);
  dec->thread_count = 1;
  avcodec_open2(dec, codec, nullptr);
  AVPacket* pkt = av_packet_alloc();
  AVFrame* frame = av_frame_alloc();
  long frames = 0;
  auto drain = [&] {
    while (avcodec_receive_frame(dec, frame) >= 0) {
      ++frames;
      av_frame_unref(frame);
    }
  };
  while (av_read_frame(fmt, pkt) >= 0) {
    if (pkt->stream_index == si) {
      avcodec_send_packet(dec, pkt);
      drain();
    }
    av_packet_unref(pkt);
  }
  avcodec_send_packet(dec, nullptr);
  drain();
  av_frame_free(&frame);
  av_packet_free(&pkt);
  avcodec_free_context(&dec);
  avformat_close_input(&fmt);
  return frames;
}

slapse::MvReaderOptions ReaderOptions(bool reduced_decode) {
  slapse::MvReaderOptions o;
  o.reduced_decode = reduced_decode;
  return o;
}

long ReadMvs(const std::string& path, bool reduced_decode) {
  auto reader = slapse::MvReader::Open(path, ReaderOptions(reduced_decode));
  if (!reader.ok()) return -1;
  slapse::FrameRecord f;
  long frames = 0;
  while ((*reader)->Next(&f).ok()) ++frames;
  return frames;
}

long RunPipeline(const std::string& path, const slapse::Intrinsics& intrinsics, bool reduced_decode,
                 Result* r) {
  auto reader = slapse::MvReader::Open(path, ReaderOptions(reduced_decode));
  if (!reader.ok()) return -1;
  slapse::Pipeline pipeline(intrinsics, (*reader)->info().mv_sigma_px());
  slapse::FrameRecord f;
  long frames = 0;
  auto add = [r](const slapse::StageTimes& t) {
    r->merge_ms += t.merge_ms;
    r->threshold_ms += t.threshold_ms;
    r->fit_ms += t.fit_ms;
    r->ekf_ms += t.ekf_ms;
    r->frame_poses_ms += t.frame_poses_ms;
    r->refine_ms += t.refine_ms;
    ++r->pairs;
  };
  while ((*reader)->Next(&f).ok()) {
    ++frames;
    auto step = pipeline.Push(f);
    if (step.ok() && step->has_value()) add((*step)->times);
  }
  // The stream's end, as `slapse run`: the open chain's pair is processed too.
  if (std::optional<slapse::PipelineStep> last = pipeline.Finish()) add(last->times);
  return frames;
}

// Runs `mode` `repeat` times and returns the best time; peak RSS is this process's.
Result MeasureHere(int mode, const std::string& path, const slapse::Intrinsics& intrinsics,
                   int repeat) {
  Result best;
  best.seconds = 1e30;
  for (int i = 0; i < repeat; ++i) {
    Result r;
    const auto t0 = Clock::now();
    // Modes: 0 bare decode; 1 / 2 reader / pipeline as shipped (reduced
    // decode); 3 / 4 the same decoding every picture in full.
    const bool reduced = mode < 3;
    r.frames = mode == 0                  ? BareDecode(path)
               : (mode == 1 || mode == 3) ? ReadMvs(path, reduced)
                                          : RunPipeline(path, intrinsics, reduced, &r);
    r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    if (r.seconds < best.seconds) best = r;
  }
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  best.peak_rss_kb = ru.ru_maxrss;
  return best;
}

// Runs one measurement in a fresh process (this binary with --measure), so
// that its peak memory is its own and not the simulator's.
Result Measure(int mode, const std::string& path, const slapse::Intrinsics& intrinsics,
               int repeat) {
  // popen runs a shell: name this binary by its real path.
  const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
  char cmd[2048];
  std::snprintf(cmd, sizeof(cmd),
                "'%s' --measure %d --repeat %d --input '%s' --fx %.9g "
                "--fy %.9g --cx %.9g --cy %.9g",
                self.c_str(), mode, repeat, path.c_str(), intrinsics.fx_px, intrinsics.fy_px,
                intrinsics.cx_px, intrinsics.cy_px);
  Result r;
  FILE* p = popen(cmd, "r");
  if (p == nullptr) return r;
  if (std::fscanf(p, "%lf %ld %ld %lf %lf %lf %lf %ld %lf %lf", &r.seconds, &r.frames,
                  &r.peak_rss_kb, &r.merge_ms, &r.threshold_ms, &r.fit_ms, &r.ekf_ms, &r.pairs,
                  &r.frame_poses_ms, &r.refine_ms) != 10) {
    r.frames = -1;
  }
  pclose(p);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  av_log_set_level(AV_LOG_ERROR);
  std::string input, gt_dir;
  int repeat = 3, measure = -1;
  slapse::Intrinsics given;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--input") && i + 1 < argc) {
      input = argv[++i];
    } else if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc) {
      repeat = std::max(1, std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--measure") && i + 1 < argc) {  // internal
      measure = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--fx") && i + 1 < argc) {
      given.fx_px = std::atof(argv[++i]);
    } else if (!std::strcmp(argv[i], "--fy") && i + 1 < argc) {
      given.fy_px = std::atof(argv[++i]);
    } else if (!std::strcmp(argv[i], "--cx") && i + 1 < argc) {
      given.cx_px = std::atof(argv[++i]);
    } else if (!std::strcmp(argv[i], "--cy") && i + 1 < argc) {
      given.cy_px = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr,
                   "usage: slapse_bench [--input FILE (a simulated drive's video)] [--repeat N]\n");
      return 2;
    }
  }
  if (measure >= 0) {
    auto reader = slapse::MvReader::Open(input);
    if (!reader.ok()) return 1;
    given.width_px = (*reader)->info().width_px;
    given.height_px = (*reader)->info().height_px;
    reader->reset();
    const Result r = MeasureHere(measure, input, given, repeat);
    std::printf("%.6f %ld %ld %.3f %.3f %.3f %.3f %ld %.3f %.3f\n", r.seconds, r.frames,
                r.peak_rss_kb, r.merge_ms, r.threshold_ms, r.fit_ms, r.ekf_ms, r.pairs,
                r.frame_poses_ms, r.refine_ms);
    return 0;
  }
  slapse::Intrinsics intrinsics;
  if (input.empty()) {
    slapse::SimulateOptions opt;
    opt.output_dir = (std::filesystem::temp_directory_path() / "slapse_bench_drive").string();
    slapse::SimulateReport rep;
    if (slapse::Status s = slapse::SimulateDrive(opt, &rep); !s.ok()) {
      std::fprintf(stderr, "slapse_bench: %s\n", s.ToString().c_str());
      return 1;
    }
    std::printf(
        "simulated the default drive (seed 1, 10 s, 640x480, MPEG-2 IBBBP): render %.1f "
        "ms/frame, encode %.1f ms/frame\n\n",
        1e3 * rep.render_s / rep.frames, 1e3 * rep.encode_s / rep.frames);
    input = rep.video_path;
  }
  gt_dir = std::filesystem::path(input).parent_path().string();
  auto gt = slapse::LoadGroundTruth(gt_dir);
  if (gt.ok()) {
    intrinsics = gt->intrinsics;
  } else {
    auto reader = slapse::MvReader::Open(input);
    if (!reader.ok()) {
      std::fprintf(stderr, "slapse_bench: %s\n", reader.status().ToString().c_str());
      return 1;
    }
    intrinsics = slapse::Intrinsics::FromHorizontalFov((*reader)->info().width_px,
                                                       (*reader)->info().height_px, 70);
  }
  const char* names[] = {"bare FFmpeg decode (no MV export)",
                         "MV reader (reduced decode + export_mvs)",
                         "SLAPSE pipeline (reader + all stages)",
                         "MV reader, every picture in full (reduced_decode off)",
                         "SLAPSE pipeline, every picture in full"};
  Result results[5];
  std::printf("input: %s, best of %d runs, 1 decoder thread\n\n", input.c_str(), repeat);
  std::printf("| stage | frames | seconds | frames/s | x bare decode | peak RSS (MiB) |\n");
  std::printf("|---|---:|---:|---:|---:|---:|\n");
  for (int mode = 0; mode < 5; ++mode) {
    results[mode] = Measure(mode, input, intrinsics, repeat);
    const Result& r = results[mode];
    std::printf("| %s | %ld | %.3f | %.0f | %.2f | %.1f |\n", names[mode], r.frames, r.seconds,
                r.frames / r.seconds, r.seconds / results[0].seconds, r.peak_rss_kb / 1024.0);
  }
  const Result& p = results[2];
  if (p.pairs > 0) {
    std::printf("\npipeline stages, mean per anchor pair (%ld pairs):\n\n", p.pairs);
    std::printf(
        "| merging | thresholding | plane fitting | EKF | window refinement | frame poses |\n"
        "|---:|---:|---:|---:|---:|---:|\n");
    std::printf("| %.2f ms | %.2f ms | %.2f ms | %.2f ms | %.2f ms | %.2f ms |\n",
                p.merge_ms / p.pairs, p.threshold_ms / p.pairs, p.fit_ms / p.pairs,
                p.ekf_ms / p.pairs, p.refine_ms / p.pairs, p.frame_poses_ms / p.pairs);
  }
  return 0;
}
