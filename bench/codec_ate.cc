// codec_ate: the same simulated drives encoded with each encoder preset
// (lab/codec EncoderPreset), run through the offline pipeline, scored against
// the truth (issue 13: H.264 IPPP against MPEG-2 IBBBP, reference handling,
// re-encode settings). Prints one Markdown row per (preset, seed) and the
// mean ATE as % of distance per preset. Drives are cached in OUT/<preset>/seed<N>.
//
//   build/bench/codec_ate --out out/codec_ate --seeds 1,2,3,4,5 --duration-s 5
//       --presets mpeg2-ibbbp,h264-baseline-ippp-2s [--uncertain-refs keep|drop|consistent]
//       [--reencode-q 4 --reencode-gop 12 --reencode-b 3 --reencode-dia 4]
//       [--min-pair-span-s 0.13]
// Seeds 1-5 are the tuning seeds (docs/TRAJECTORY.md): choose settings on them only.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/codec/video_encoder.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/simulate.h"

namespace {

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

struct Args {
  std::string out = "out/codec_ate";
  std::vector<std::string> seeds = {"1", "2", "3", "4", "5"};
  std::vector<std::string> presets = {"mpeg2-ibbbp", "h264-baseline-ippp-2s"};
  double duration_s = 5.0;
  slapse::MvReaderOptions reader;
  slapse::PipelineOptions pipeline;
};

bool Parse(int argc, char** argv, Args* a) {
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--out") {
      a->out = v;
    } else if (k == "--seeds") {
      a->seeds = Split(v);
    } else if (k == "--presets") {
      a->presets = Split(v);
    } else if (k == "--duration-s") {
      a->duration_s = std::atof(v.c_str());
    } else if (k == "--uncertain-refs") {
      using U = slapse::MergeOptions::UncertainRefs;
      a->pipeline.merge.uncertain_refs = v == "keep"   ? U::kKeep
                                         : v == "drop" ? U::kDrop
                                                       : U::kConsistent;
    } else if (k == "--min-pair-span-s") {
      a->pipeline.merge.min_pair_span_s = std::atof(v.c_str());
    } else if (k == "--reencode-q") {
      a->reader.reencode_options.quantiser = std::atoi(v.c_str());
    } else if (k == "--reencode-gop") {
      a->reader.reencode_options.gop_size = std::atoi(v.c_str());
    } else if (k == "--reencode-b") {
      a->reader.reencode_options.b_frames = std::atoi(v.c_str());
    } else if (k == "--reencode-dia") {
      a->reader.reencode_options.dia_size = std::atoi(v.c_str());
    } else {
      std::fprintf(stderr, "unknown flag %s\n", k.c_str());
      return false;
    }
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace slapse;
  Args a;
  if (!Parse(argc, argv, &a)) return 2;
  std::printf(
      "| preset | seed | D (m) | poses / frames | ATE (m) | ATE %% of D | eps_D | "
      "re-encode / decode CPU |\n|---|---|---:|---:|---:|---:|---:|---:|\n");
  for (const std::string& preset : a.presets) {
    double sum_pct = 0;
    int n = 0;
    for (const std::string& seed : a.seeds) {
      const std::string dir = a.out + "/" + preset + "/seed" + seed;
      SimulateOptions so;
      so.seed = std::stoull(seed);
      so.duration_s = a.duration_s;
      so.output_dir = dir;
      auto eo = EncoderPreset(preset, so.fps);
      if (!eo.ok()) {
        std::fprintf(stderr, "%s\n", eo.status().ToString().c_str());
        return 2;
      }
      so.encoder = *eo;
      if (eo->codec == VideoCodec::kMjpeg) so.video_name = "drive.mkv";
      const std::string video = dir + "/" + so.video_name;
      if (!std::filesystem::exists(dir + "/meta.json")) {
        SimulateReport report;
        if (Status s = SimulateDrive(so, &report); !s.ok()) {
          std::fprintf(stderr, "simulate: %s\n", s.ToString().c_str());
          return 1;
        }
      }
      auto gt = LoadGroundTruth(dir);
      auto reader = MvReader::Open(video, a.reader);
      if (!gt.ok() || !reader.ok()) {
        std::fprintf(stderr, "%s: cannot open\n", dir.c_str());
        return 1;
      }
      Pipeline pipeline(gt->intrinsics, (*reader)->info().mv_sigma_px(), a.pipeline);
      FrameRecord f;
      while ((*reader)->Next(&f).ok()) {
        if (!pipeline.Push(f).ok()) break;
      }
      pipeline.Finish();  // the stream's end, as `slapse run`
      std::vector<TimedPose> est;
      for (const auto& p : pipeline.trajectory())
        est.push_back({p.index, p.timestamp_s, p.world_from_cam});
      auto e = EvaluateTrajectory(est, TruthPoses(*gt));
      const ReadStats& st = (*reader)->stats();
      char cost[32] = "-";
      if (st.reencode_cpu_s > 0)
        std::snprintf(cost, sizeof(cost), "%.1fx", st.reencode_cpu_s / st.decode_cpu_s);
      if (!e.ok()) {
        std::printf("| %s | %s | - | %zu / %lld | - | - | - | %s |\n", preset.c_str(), seed.c_str(),
                    est.size(), static_cast<long long>(st.frames), cost);
        continue;
      }
      const double pct = 100.0 * e->ate_rmse_m / e->distance_m;
      sum_pct += pct;
      ++n;
      std::printf("| %s | %s | %.1f | %zu / %lld | %.3f | %.2f %% | %.2f %% | %s |\n",
                  preset.c_str(), seed.c_str(), e->distance_m, est.size(),
                  static_cast<long long>(st.frames), e->ate_rmse_m, pct, 100.0 * e->eps_D, cost);
      std::fflush(stdout);
    }
    std::printf("| %s | mean of %d | | | | %.2f %% | | |\n", preset.c_str(), n,
                n > 0 ? sum_pct / n : 0.0);
    std::fflush(stdout);
  }
  return 0;
}
