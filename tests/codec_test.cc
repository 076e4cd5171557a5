// What IP cameras send (issue 13), on real encoder output: codecs without
// exported vectors re-encoded in-process (HEVC, VP9, MJPEG) or refused on
// request, a resolution change mid-stream (aspect kept: rescaled and said;
// aspect changed: a precise error), timestamp gaps and variable frame rate
// read from pts, and the camera-like encoder presets.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/merge/mv_merge.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using testing::MakeTempDir;
using testing::ReadFileBytes;
using testing::RunCommand;
using testing::WritePan;

constexpr double kVx = 1.5;  // pan, px per frame
constexpr double kVy = -0.5;
constexpr int kFrames = 30;

std::vector<FrameRecord> ReadAll(MvReader* reader, Status* end) {
  std::vector<FrameRecord> frames;
  FrameRecord f;
  while ((*end = reader->Next(&f)).ok()) frames.push_back(f);
  return frames;
}

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// Median past-vector error of a P frame against the pan: a block of frame j
// referring to anchor r moved by (r - j) * v (tests/test_streams.h).
double MedianPError(const FrameRecord& f, double vx, double vy) {
  std::vector<double> err;
  const double steps = static_cast<double>(f.prev_anchor_index - f.index);
  for (const MotionVector& mv : f.mvs) {
    if (mv.direction != RefDirection::kPast) continue;
    err.push_back(std::hypot(mv.dx_px - steps * vx, mv.dy_px - steps * vy));
  }
  return Median(err);
}

struct ReencodeCase {
  const char* preset;  // lab/codec EncoderPreset
  const char* ext;
  const char* codec;  // FFmpeg's name of the stream's codec
};

class ReencodeTest : public ::testing::TestWithParam<ReencodeCase> {};

// A stream whose codec exports no vectors comes out of MvReader as a
// re-encoded MPEG-2 IBBBP stream: every frame, in display order, with the
// source's timestamps and vectors that match the known pan.
TEST_P(ReencodeTest, CodecWithoutVectorsIsReencodedWithCorrectVectorsAndTimes) {
  const ReencodeCase& rc = GetParam();
  auto eo = EncoderPreset(rc.preset, 30.0);
  ASSERT_TRUE(eo.ok()) << eo.status().ToString();
  const std::string path = MakeTempDir("reencode") + "/pan." + rc.ext;
  ASSERT_TRUE(WritePan(path, *eo, kFrames, kVx, kVy).ok());

  for (const bool from_bytes : {false, true}) {
    SCOPED_TRACE(from_bytes ? "byte source" : "file");
    auto reader = from_bytes
                      ? MvReader::Open(std::make_unique<MemoryByteSource>(ReadFileBytes(path)))
                      : MvReader::Open(path);
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    EXPECT_EQ((*reader)->info().reencoded_from, rc.codec);
    EXPECT_EQ((*reader)->info().codec_name, kReencodeCodec);
    Status end;
    const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
    EXPECT_EQ(end.code(), StatusCode::kOutOfRange) << end.ToString();
    ASSERT_EQ(frames.size(), static_cast<size_t>(kFrames));
    int p_frames = 0, b_frames = 0;
    for (size_t i = 0; i < frames.size(); ++i) {
      const FrameRecord& f = frames[i];
      EXPECT_EQ(f.index, static_cast<int64_t>(i));
      // The source's presentation times (30 fps), not the re-encoder's clock.
      EXPECT_NEAR(f.timestamp_s, i / 30.0, 1e-3) << "frame " << i;
      if (f.type == PictureType::kB) ++b_frames;
      // (The stream's last anchor may close a shorter run, and comes out of
      // the final flush without vectors.)
      if (f.type != PictureType::kP || f.mvs.empty() || i + 4 >= frames.size()) continue;
      ++p_frames;
      EXPECT_EQ(f.prev_anchor_index, f.index - 4) << "IBBBP: anchors 4 frames apart";
      EXPECT_LT(MedianPError(f, kVx, kVy), 0.5) << "frame " << i;
    }
    EXPECT_GE(p_frames, 4);
    EXPECT_GE(b_frames, 15);
    const ReadStats& st = (*reader)->stats();
    EXPECT_GT(st.reencode_cpu_s, 0.0);
    EXPECT_GT(st.decode_cpu_s, 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Codecs, ReencodeTest,
    ::testing::Values(ReencodeCase{"hevc", "ts", "hevc"}, ReencodeCase{"hevc", "mkv", "hevc"},
                      ReencodeCase{"vp9", "webm", "vp9"}, ReencodeCase{"mjpeg", "mkv", "mjpeg"}),
    [](const auto& info) { return std::string(info.param.codec) + "_" + info.param.ext; });

TEST(ReencodeTest, RefuseOptionGivesFailedPreconditionNamingTheCodec) {
  auto eo = EncoderPreset("hevc", 30.0);
  ASSERT_TRUE(eo.ok());
  const std::string path = MakeTempDir("refuse") + "/pan.ts";
  ASSERT_TRUE(WritePan(path, *eo, 8, kVx, kVy).ok());
  MvReaderOptions o;
  o.reencode = false;
  auto reader = MvReader::Open(path, o);
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(reader.status().message().find("'hevc'"), std::string::npos)
      << reader.status().message();
  EXPECT_NE(reader.status().message().find("re-encoding is off"), std::string::npos);
  // The default re-encodes the same file.
  EXPECT_TRUE(MvReader::Open(path).ok());
}

TEST(ReencodeTest, OptionsAreChecked) {
  ReencodeOptions o;
  EXPECT_TRUE(o.Check().ok());
  o.quantiser = 0;
  EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
  o = ReencodeOptions{};
  o.gop_size = 0;
  EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
}

// Two clips joined by FFmpeg's concat demuxer (stream copy, continuous
// timestamps), as a camera that switches its resolution sends them.
std::string Concat(const std::string& dir, const std::string& a, const std::string& b,
                   const std::string& ext) {
  {
    std::ofstream list(dir + "/list.txt");
    list << "file '" << a << "'\nfile '" << b << "'\n";
  }
  const std::string out = dir + "/joined." + ext;
  const int rc = RunCommand("ffmpeg -nostdin -loglevel error -y -f concat -safe 0 -i " + dir +
                            "/list.txt -c copy " + out);
  return rc == 0 ? out : "";
}

struct ResizeCase {
  const char* preset;
  const char* ext;
};

class ResolutionChangeTest : public ::testing::TestWithParam<ResizeCase> {};

// 320x240 then 160x120 (aspect kept, the pan halved with the image): the
// reader says so in a note and reads the second clip's vectors on the first
// clip's grid, so they match the first clip's pan in its pixels.
TEST_P(ResolutionChangeTest, AspectKeptIsRescaledAndSaid) {
  auto eo = EncoderPreset(GetParam().preset, 30.0);
  ASSERT_TRUE(eo.ok());
  const std::string ext = GetParam().ext;
  const std::string dir = MakeTempDir("resize");
  ASSERT_TRUE(WritePan(dir + "/a." + ext, *eo, 24, kVx, kVy, 320, 240).ok());
  ASSERT_TRUE(WritePan(dir + "/b." + ext, *eo, 24, kVx / 2, kVy / 2, 160, 120).ok());
  const std::string joined = Concat(dir, dir + "/a." + ext, dir + "/b." + ext, ext);
  ASSERT_FALSE(joined.empty());
  auto reader = MvReader::Open(joined);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  Status end;
  const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
  EXPECT_EQ(end.code(), StatusCode::kOutOfRange) << end.ToString();
  // 48, or 47 for MPEG-2: FFmpeg's decoder drops the old sequence's last
  // (delayed) anchor at the new sequence header (ffprobe counts 47 too).
  EXPECT_GE(frames.size(), 47u);
  EXPECT_LE(frames.size(), 48u);
  const ReadStats& st = (*reader)->stats();
  ASSERT_EQ(st.notes.size(), 1u);
  EXPECT_NE(st.notes[0].find("320x240 to 160x120"), std::string::npos) << st.notes[0];
  EXPECT_NE(st.notes[0].find("aspect kept"), std::string::npos) << st.notes[0];
  EXPECT_EQ((*reader)->info().width_px, 320);
  int checked = 0;
  for (const FrameRecord& f : frames) {
    if (f.type != PictureType::kP || f.index < 28 || f.prev_anchor_index < 24) continue;
    EXPECT_LT(MedianPError(f, kVx, kVy), 0.6) << "frame " << f.index;
    ++checked;
  }
  EXPECT_GE(checked, 2);
}

// 320x240 then 320x180: the intrinsics cannot follow; the frames before the
// change are yielded, then a FAILED_PRECONDITION that names both sizes.
TEST_P(ResolutionChangeTest, AspectChangedEndsWithPreciseError) {
  auto eo = EncoderPreset(GetParam().preset, 30.0);
  ASSERT_TRUE(eo.ok());
  const std::string ext = GetParam().ext;
  const std::string dir = MakeTempDir("reaspect");
  ASSERT_TRUE(WritePan(dir + "/a." + ext, *eo, 24, kVx, kVy, 320, 240).ok());
  ASSERT_TRUE(WritePan(dir + "/b." + ext, *eo, 24, kVx, kVy, 320, 180).ok());
  const std::string joined = Concat(dir, dir + "/a." + ext, dir + "/b." + ext, ext);
  ASSERT_FALSE(joined.empty());
  auto reader = MvReader::Open(joined);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  Status end;
  const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
  EXPECT_EQ(end.code(), StatusCode::kFailedPrecondition) << end.ToString();
  EXPECT_NE(end.message().find("from 320x240 to 320x180"), std::string::npos) << end.message();
  EXPECT_NE(end.message().find("aspect ratio"), std::string::npos) << end.message();
  EXPECT_GE(frames.size(), 20u);
  EXPECT_LE(frames.size(), 24u);
  for (const FrameRecord& f : frames) EXPECT_LT(f.index, 24);
}

INSTANTIATE_TEST_SUITE_P(Codecs, ResolutionChangeTest,
                         ::testing::Values(ResizeCase{"h264-baseline-ippp-1s", "ts"},
                                           ResizeCase{"mpeg2-ibbbp", "ts"},
                                           ResizeCase{"hevc", "ts"}),
                         [](const auto& info) {
                           std::string n = info.param.preset;
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

// Timestamps come from pts: a stream with a 1 s gap (dropped frames, "smart
// FPS") and a stretch at half the frame rate keeps them, for direct and
// re-encoded reading alike.
TEST(TimestampTest, GapsAndVariableFrameRateComeFromPts) {
  for (const char* preset : {"h264-baseline-ippp-2s", "hevc"}) {
    SCOPED_TRACE(preset);
    auto eo = EncoderPreset(preset, 30.0);
    ASSERT_TRUE(eo.ok());
    eo->b_frames = 0;  // pts = dts order, so setts can rewrite both alike
    const std::string dir = MakeTempDir("vfr");
    ASSERT_TRUE(WritePan(dir + "/cfr.ts", *eo, 30, kVx, kVy).ok());
    // Frames 0-9 at 30 fps, then a 1 s gap, then 15 fps: in 90 kHz ticks a
    // frame is 3000; from N = 10 on pts += 90000 + (N-10)*3000. (No commas:
    // the bitstream filter list splits on them; not(not(floor(N/10))) is N >= 10.)
    const std::string expr = "PTS+not(not(floor(N/10)))*(90000+(N-10)*3000)";
    ASSERT_EQ(RunCommand("ffmpeg -nostdin -loglevel error -y -i " + dir +
                         "/cfr.ts -c copy -bsf:v 'setts=pts=" + expr + ":dts=" + expr + "' " + dir +
                         "/vfr.ts"),
              0);
    auto reader = MvReader::Open(dir + "/vfr.ts");
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    Status end;
    const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
    ASSERT_EQ(frames.size(), 30u) << end.ToString();
    for (const FrameRecord& f : frames) {
      const double want =
          f.index < 10 ? f.index / 30.0 : f.index / 30.0 + 1.0 + (f.index - 10) / 30.0;
      EXPECT_NEAR(f.timestamp_s, want, 2e-3) << "frame " << f.index;
    }
  }
}

// A still camera (no motion at all) gives no poses, and every pipeline step
// says why instead of a silent empty result (the session's no-poses reason
// and `slapse run`'s "no poses" line repeat the last one).
TEST(NoMotionTest, StillStreamSaysNoReliableMotion) {
  for (const char* preset : {"mpeg2-ibbbp", "h264-baseline-ippp-1s"}) {
    SCOPED_TRACE(preset);
    auto eo = EncoderPreset(preset, 30.0);
    ASSERT_TRUE(eo.ok());
    const std::string path = MakeTempDir("still") + "/still.ts";
    ASSERT_TRUE(WritePan(path, *eo, 40, 0.0, 0.0).ok());
    auto reader = MvReader::Open(path);
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    Intrinsics k;
    k.fx_px = k.fy_px = 300;
    k.cx_px = 159.5;
    k.cy_px = 119.5;
    k.width_px = 320;
    k.height_px = 240;
    Pipeline pipeline(k, (*reader)->info().mv_sigma_px());
    FrameRecord f;
    int steps = 0;
    while ((*reader)->Next(&f).ok()) {
      auto step = pipeline.Push(f);
      ASSERT_TRUE(step.ok()) << step.status().ToString();
      if (!step->has_value()) continue;
      ++steps;
      EXPECT_FALSE((*step)->tracking);
      EXPECT_NE((*step)->note.find("no reliable motion"), std::string::npos) << (*step)->note;
    }
    EXPECT_GE(steps, 5);
    EXPECT_TRUE(pipeline.trajectory().empty());
  }
}

// Merging options for the pan streams: one pair per segment, so the
// references stay visible.
MergeOptions PanMergeOptions(MergeOptions::UncertainRefs uncertain, bool pyramid_top_b = true) {
  MergeOptions mo;
  mo.uncertain_refs = uncertain;
  mo.pyramid_top_b = pyramid_top_b;
  mo.min_pair_span_s = 0;  // one pair per P frame
  return mo;
}

// Calls fn(later anchor index, correspondence, whether the later P frame's
// reference is uncertain, how far the displacement misses the pan's in px)
// for every merged correspondence of a pan stream.
template <typename Fn>
void ForEachPanCorrespondence(const std::string& path, const MergeOptions& mo, Fn fn) {
  auto reader = MvReader::Open(path);
  if (!reader.ok()) return;
  SegmentMerger merger(320, 240, (*reader)->info().mv_sigma_px(), mo);
  FrameRecord f;
  while ((*reader)->Next(&f).ok()) {
    const bool uncertain_p = f.type == PictureType::kP && !f.reference_certain;
    auto pair = merger.Push(f);
    if (!pair.has_value()) continue;
    const double steps = static_cast<double>(pair->earlier_index - pair->later_index);
    for (const Correspondence& c : pair->correspondences) {
      fn(pair->later_index, c, uncertain_p,
         Eigen::Vector2d(c.x_earlier_px - c.x_later_px - steps * Eigen::Vector2d(kVx, kVy)));
    }
  }
}

// Merged pairs of a pan stream under `uncertain`: the fraction of
// correspondences whose displacement misses the pan's by more than 1 px (a
// vector to another reference than the pair's earlier anchor), and how many.
struct PairErrors {
  int correspondences = 0, wrong = 0, from_uncertain = 0;
  int with_indirect = 0, wrong_with_indirect = 0;  // correspondences with B-frame candidates
};
PairErrors MergePan(const std::string& path, MergeOptions::UncertainRefs uncertain,
                    bool pyramid_top_b = true) {
  PairErrors out;
  ForEachPanCorrespondence(
      path, PanMergeOptions(uncertain, pyramid_top_b),
      [&](int64_t, const Correspondence& c, bool uncertain_p, const Eigen::Vector2d& error_px) {
        ++out.correspondences;
        out.from_uncertain += uncertain_p && c.n_direct > 0;
        const bool wrong = error_px.norm() > 1.0;
        out.wrong += wrong;
        out.with_indirect += c.n_indirect > 0;
        out.wrong_with_indirect += wrong && c.n_indirect > 0;
      });
  return out;
}

// Per merged cell of a pan stream, keyed by (later anchor index, MB index):
// how far its displacement misses the pan's, in px.
std::map<std::pair<int64_t, int>, Eigen::Vector2d> PanCellErrors(const std::string& path,
                                                                 const MergeOptions& mo) {
  std::map<std::pair<int64_t, int>, Eigen::Vector2d> out;
  ForEachPanCorrespondence(
      path, mo,
      [&](int64_t later_index, const Correspondence& c, bool, const Eigen::Vector2d& error_px) {
        out[{later_index, c.mb_index}] = error_px;
      });
  return out;
}

// H.264 High with a B-pyramid and 3 references (x264): the reader marks its P
// frames' references uncertain (and not those of Baseline IPPP with one);
// the merger never mixes them silently: kDrop uses none of their vectors,
// kConsistent keeps fewer wrong ones than kKeep.
TEST(ReferenceTest, BPyramidThreeRefsAreMarkedAndNotMixed) {
  const std::string dir = MakeTempDir("refs");
  auto bpyr = EncoderPreset("h264-high-bpyr-3ref", 30.0);
  auto ippp = EncoderPreset("h264-baseline-ippp-1s", 30.0);
  ASSERT_TRUE(bpyr.ok() && ippp.ok());
  bpyr->gop_size = 60;
  ASSERT_TRUE(WritePan(dir + "/bpyr.ts", *bpyr, 40, kVx, kVy).ok());
  ASSERT_TRUE(WritePan(dir + "/ippp.ts", *ippp, 20, kVx, kVy).ok());
  {
    auto reader = MvReader::Open(dir + "/bpyr.ts");
    ASSERT_TRUE(reader.ok());
    Status end;
    const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
    EXPECT_TRUE((*reader)->info().b_pyramid);
    EXPECT_TRUE((*reader)->info().extra_references());
    int uncertain_p = 0;
    for (const FrameRecord& f : frames)
      uncertain_p += f.type == PictureType::kP && !f.reference_certain;
    EXPECT_GE(uncertain_p, 5);
  }
  {
    auto reader = MvReader::Open(dir + "/ippp.ts");
    ASSERT_TRUE(reader.ok());
    Status end;
    for (const FrameRecord& f : ReadAll(reader->get(), &end)) EXPECT_TRUE(f.reference_certain);
  }
  using U = MergeOptions::UncertainRefs;
  const PairErrors keep = MergePan(dir + "/bpyr.ts", U::kKeep);
  const PairErrors drop = MergePan(dir + "/bpyr.ts", U::kDrop);
  const PairErrors consistent = MergePan(dir + "/bpyr.ts", U::kConsistent);
  EXPECT_GT(keep.from_uncertain, 0);
  EXPECT_EQ(drop.from_uncertain, 0);
  ASSERT_GT(consistent.correspondences, 0);
  EXPECT_LE(consistent.wrong * keep.correspondences, keep.wrong * consistent.correspondences)
      << "consistent " << consistent.wrong << "/" << consistent.correspondences << ", keep "
      << keep.wrong << "/" << keep.correspondences;
  EXPECT_LT(consistent.wrong, 0.05 * consistent.correspondences);
  // The pyramid's top B frame adds indirect candidates (MergeOptions::
  // pyramid_top_b) without wrong ones: its references are the anchors.
  const PairErrors direct_only = MergePan(dir + "/bpyr.ts", U::kConsistent, false);
  EXPECT_EQ(direct_only.with_indirect, 0);
  EXPECT_GT(consistent.with_indirect, consistent.correspondences / 2)
      << consistent.with_indirect << " of " << consistent.correspondences;
  EXPECT_LT(consistent.wrong_with_indirect, 0.02 * consistent.with_indirect);
  // A cell whose direct and top-B candidates disagree gives none. Which cells
  // those are is x264's choice, and its choices differ with the CPU's SIMD
  // paths: on some machines one top B frame refers a whole region to the
  // pyramid's previous B frame (2 frames off, (-3, 1) px) and those cells drop
  // out. So: every cell lost against direct only is one whose top-B candidate
  // alone misses the direct one by more than the merge gate, and most stay.
  const MergeOptions mo = PanMergeOptions(U::kConsistent);
  const auto both = PanCellErrors(dir + "/bpyr.ts", mo);
  MergeOptions direct_mo = mo, top_b_mo = mo;
  direct_mo.use_indirect = false;
  top_b_mo.use_direct = false;
  const auto direct = PanCellErrors(dir + "/bpyr.ts", direct_mo);
  const auto top_b = PanCellErrors(dir + "/bpyr.ts", top_b_mo);
  ASSERT_EQ(direct.size(), static_cast<size_t>(direct_only.correspondences));
  double sigma_px = 0;
  {
    auto reader = MvReader::Open(dir + "/bpyr.ts");
    ASSERT_TRUE(reader.ok());
    sigma_px = (*reader)->info().mv_sigma_px();
  }
  const double gate_px = MergeNoiseGatePx(true, false, sigma_px, mo);  // direct against top B
  int lost = 0, lost_without_disagreement = 0;
  for (const auto& [cell, error_px] : direct) {
    if (both.count(cell) != 0) continue;
    ++lost;
    const auto it = top_b.find(cell);
    if (it == top_b.end() || (it->second - error_px).norm() <= gate_px) {
      ++lost_without_disagreement;
      ADD_FAILURE() << "pair ending at " << cell.first << ", MB " << cell.second
                    << " lost without a disagreeing top-B candidate";
    }
  }
  EXPECT_EQ(lost_without_disagreement, 0);
  EXPECT_GE(consistent.correspondences, 0.85 * direct_only.correspondences);
  std::printf(
      "pyramid pan: %d correspondences (%d wrong, %d with a top-B candidate, %d of them "
      "wrong); direct only %d (%d wrong); %d cells lost to a disagreeing top-B candidate\n",
      consistent.correspondences, consistent.wrong, consistent.with_indirect,
      consistent.wrong_with_indirect, direct_only.correspondences, direct_only.wrong, lost);
}

// The low-rate camera preset keeps to its bitrate (VBV cap), where CRF 20
// spends what the picture asks for.
TEST(PresetTest, LowRatePresetKeepsTheCamerasBitrate) {
  auto low = EncoderPreset("h264-baseline-ippp-2s-lowrate", 30.0);
  ASSERT_TRUE(low.ok());
  EXPECT_EQ(low->gop_size, 60);
  EXPECT_EQ(low->b_frames, 0);
  EXPECT_NEAR(low->h264_bits_per_pixel_s * 640 * 480, 2e6, 1.0);
  auto crf = EncoderPreset("h264-baseline-ippp-2s", 30.0);
  ASSERT_TRUE(crf.ok());
  EXPECT_EQ(crf->h264_bits_per_pixel_s, 0.0);
  const std::string dir = MakeTempDir("lowrate");
  constexpr int kFrames = 90;  // 3 s
  ASSERT_TRUE(WritePan(dir + "/low.ts", *low, kFrames, kVx, kVy).ok());
  ASSERT_TRUE(WritePan(dir + "/crf.ts", *crf, kFrames, kVx, kVy).ok());
  const double seconds = kFrames / 30.0;
  const double low_bps = 8.0 * std::filesystem::file_size(dir + "/low.ts") / seconds;
  const double crf_bps = 8.0 * std::filesystem::file_size(dir + "/crf.ts") / seconds;
  const double target_bps = low->h264_bits_per_pixel_s * 320 * 240;  // 0.5 Mbit/s
  // The MPEG-TS container adds a few percent.
  EXPECT_LT(low_bps, 1.3 * target_bps) << low_bps;
  EXPECT_GT(low_bps, 0.5 * target_bps) << low_bps;
  EXPECT_GT(crf_bps, 1.5 * low_bps) << crf_bps << " vs " << low_bps;
  // It still reads as H.264 with vectors on every P frame.
  auto reader = MvReader::Open(dir + "/low.ts");
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  Status end;
  const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
  ASSERT_EQ(frames.size(), static_cast<size_t>(kFrames)) << end.ToString();
  EXPECT_FALSE(frames[1].mvs.empty());
  EncoderOptions mpeg2_rate;
  mpeg2_rate.h264_bits_per_pixel_s = 6.5;
  EXPECT_EQ(VideoEncoder::Open(dir + "/x.ts", 320, 240, mpeg2_rate).status().code(),
            StatusCode::kInvalidArgument);
}

// x264 left at its defaults (what the "x264 defaults" streams are):
// adaptive B frames in a pyramid with 3 references, read and merged without
// mixing references.
TEST(PresetTest, X264DefaultsGiveAPyramidThatMergesCleanly) {
  const std::string dir = MakeTempDir("x264_defaults");
  auto p = EncoderPreset("h264-x264-defaults", 30.0);
  ASSERT_TRUE(p.ok());
  EXPECT_TRUE(p->h264_x264_defaults);
  ASSERT_TRUE(WritePan(dir + "/pan.ts", *p, 40, kVx, kVy).ok());
  auto reader = MvReader::Open(dir + "/pan.ts");
  ASSERT_TRUE(reader.ok());
  Status end;
  const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
  ASSERT_EQ(frames.size(), 40u) << end.ToString();
  int b_frames = 0;
  for (const FrameRecord& f : frames) b_frames += f.type == PictureType::kB;
  EXPECT_GT(b_frames, 10);
  EXPECT_TRUE((*reader)->info().b_pyramid);
  EXPECT_GE((*reader)->info().max_ref_frames, 3);
  const PairErrors e = MergePan(dir + "/pan.ts", MergeOptions::UncertainRefs::kConsistent);
  ASSERT_GT(e.correspondences, 0);
  EXPECT_GT(e.with_indirect, 0);
  EXPECT_LT(e.wrong, 0.05 * e.correspondences) << e.wrong << " of " << e.correspondences;
}

TEST(PresetTest, NamesParseAndUnknownNamesListTheChoices) {
  for (const std::string& name : EncoderPresetNames()) {
    auto p = EncoderPreset(name, 25.0);
    EXPECT_TRUE(p.ok()) << name << ": " << p.status().ToString();
  }
  auto b = EncoderPreset("h264-baseline-ippp-4s", 25.0);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->gop_size, 100);
  EXPECT_EQ(b->b_frames, 0);
  EXPECT_EQ(b->h264_profile, "baseline");
  auto h = EncoderPreset("h264-high-bpyr-3ref", 25.0);
  ASSERT_TRUE(h.ok());
  EXPECT_TRUE(h->h264_b_pyramid);
  EXPECT_EQ(h->h264_refs, 3);
  auto il = EncoderPreset("mpeg2-interlaced", 25.0);
  ASSERT_TRUE(il.ok());
  EXPECT_TRUE(il->interlaced);
  EXPECT_EQ(il->codec, VideoCodec::kMpeg2);
  EXPECT_EQ(il->b_frames, 3);
  EncoderOptions h264_interlaced = *il;
  h264_interlaced.codec = VideoCodec::kH264;
  auto refused = VideoEncoder::Open(MakeTempDir("interlaced") + "/x.ts", 320, 240, h264_interlaced);
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  auto bad = EncoderPreset("h264-fancy", 25.0);
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("h264-high-bpyr-3ref"), std::string::npos);
}

}  // namespace
}  // namespace slapse
