// Pins the semantics of exported motion vectors on streams with known motion,
// encoded by the real MPEG-2, MPEG-4 Part 2 and H.264 encoders.
#include "core/mv/mv_reader.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/mv/mb_texture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using testing::MakeTempDir;
using testing::WritePan;

constexpr double kVx = 1.5;  // pan, px per frame (half-pel representable)
constexpr double kVy = -0.5;
constexpr int kFrames = 33;

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

struct CodecCase {
  VideoCodec codec;
  const char* ext;
  int denom;  // expected MV precision denominator
  bool qpel = false;
};

class PanTest : public ::testing::TestWithParam<CodecCase> {};

TEST_P(PanTest, SignsDirectionsAndGopIndexingMatchTheKnownPan) {
  const CodecCase& cc = GetParam();
  const std::string path = MakeTempDir("pan") + "/pan." + cc.ext;
  EncoderOptions eo;
  eo.codec = cc.codec;
  eo.b_frames = 3;
  eo.gop_size = 12;
  eo.quality = cc.codec == VideoCodec::kH264 ? 18 : 3;
  eo.mpeg4_qpel = cc.qpel;
  ASSERT_TRUE(WritePan(path, eo, kFrames, kVx, kVy).ok());

  auto reader = MvReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  Status end;
  const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
  EXPECT_EQ(end.code(), StatusCode::kOutOfRange) << end.ToString();
  ASSERT_EQ(static_cast<int>(frames.size()), kFrames);
  EXPECT_EQ((*reader)->info().mv_precision_denom, cc.denom);
  EXPECT_EQ((*reader)->info().max_consecutive_b, 3);
  EXPECT_EQ((*reader)->info().width_px, 320);
  EXPECT_EQ((*reader)->info().b_frame_mvs, cc.codec != VideoCodec::kMpeg4);

  int checked_frames = 0;
  size_t total_b_past = 0, total_b_future = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameRecord& f = frames[i];
    SCOPED_TRACE("frame " + std::to_string(i) + " type " + PictureTypeChar(f.type));
    EXPECT_EQ(f.index, static_cast<int64_t>(i));  // display order
    EXPECT_NEAR(f.timestamp_s, i / 30.0, 1e-3);
    EXPECT_FALSE(f.corrupt);
    if (i == 0) {
      EXPECT_EQ(f.type, PictureType::kI);
    }
    // GOP: I B B B P B B B P ... with every B between its two anchors.
    if (f.type == PictureType::kB) {
      ASSERT_GE(f.prev_anchor_index, 0);
      EXPECT_LT(f.prev_anchor_index, f.index);
      if (f.next_anchor_index >= 0) {
        EXPECT_GT(f.next_anchor_index, f.index);
        EXPECT_LE(f.next_anchor_index - f.prev_anchor_index, 4);  // n_B <= 3
        EXPECT_TRUE(IsAnchor(frames[f.next_anchor_index].type));
      }
      EXPECT_TRUE(IsAnchor(frames[f.prev_anchor_index].type));
    } else if (f.type == PictureType::kP) {
      EXPECT_TRUE(IsAnchor(frames[f.prev_anchor_index].type));
      EXPECT_LT(f.prev_anchor_index, f.index);
    }
    if (f.type == PictureType::kI) {
      EXPECT_TRUE(f.mvs.empty()) << "intra frames carry no motion";
      continue;
    }
    if (f.type == PictureType::kB && !(*reader)->info().b_frame_mvs) {
      EXPECT_TRUE(f.mvs.empty()) << "stale B-frame vectors must not be yielded";
      continue;
    }
    if (i + 1 == frames.size() && cc.codec != VideoCodec::kH264) {
      // FFmpeg 5.1's MPEG decoders return the last anchor at the final flush
      // without its side data: a stream's last P frame carries no vectors.
      // Pinned here so the pipeline's handling of it stays deliberate.
      EXPECT_TRUE(f.mvs.empty());
      continue;
    }
    // Interior blocks: the content there exists in the reference too.
    std::vector<double> past_dx, past_dy, fut_dx, fut_dy;
    int past_exact = 0, fut_exact = 0;
    const double step = 1.0 / cc.denom;
    const double past_gap = static_cast<double>(f.index - f.prev_anchor_index);
    const double fut_gap = static_cast<double>(f.next_anchor_index - f.index);
    for (const MotionVector& mv : f.mvs) {
      if (mv.x_px < 40 || mv.x_px > 280 || mv.y_px < 40 || mv.y_px > 200) continue;
      // Sub-pixel values come through, not truncated integers.
      EXPECT_NEAR(mv.dx_px * cc.denom, std::round(mv.dx_px * cc.denom), 1e-4);
      if (mv.direction == RefDirection::kPast) {
        past_dx.push_back(mv.dx_px);
        past_dy.push_back(mv.dy_px);
        past_exact += std::abs(mv.dx_px + past_gap * kVx) <= step + 1e-6 &&
                      std::abs(mv.dy_px + past_gap * kVy) <= step + 1e-6;
      } else {
        fut_dx.push_back(mv.dx_px);
        fut_dy.push_back(mv.dy_px);
        fut_exact += std::abs(mv.dx_px - fut_gap * kVx) <= step + 1e-6 &&
                     std::abs(mv.dy_px - fut_gap * kVy) <= step + 1e-6;
      }
    }
    // A block at c in frame j refers to c + (r - j) * v in reference r: past
    // vectors point against the pan, future vectors along it. An H.264 B block
    // picks L0, L1 or both, so a direction is judged where it has >= 8 blocks.
    if (f.type == PictureType::kP) {
      ASSERT_GE(past_dx.size(), 20u) << "P frames have past (L0) vectors";
      EXPECT_TRUE(fut_dx.empty()) << "P frames refer only to the past";
    } else {
      ASSERT_GE(past_dx.size() + fut_dx.size(), 20u) << "B frames have vectors";
      total_b_past += past_dx.size();
      total_b_future += fut_dx.size();
    }
    if (past_dx.size() >= 8) {
      EXPECT_NEAR(Median(past_dx), -past_gap * kVx, step);
      EXPECT_NEAR(Median(past_dy), -past_gap * kVy, step);
      EXPECT_GE(past_exact, 0.8 * past_dx.size());
    }
    if (fut_dx.size() >= 8) {
      ASSERT_EQ(f.type, PictureType::kB);
      EXPECT_NEAR(Median(fut_dx), fut_gap * kVx, step);
      EXPECT_NEAR(Median(fut_dy), fut_gap * kVy, step);
      EXPECT_GE(fut_exact, 0.8 * fut_dx.size());
    }
    ++checked_frames;
  }
  const int i_frames =
      static_cast<int>(std::count_if(frames.begin(), frames.end(), [](const FrameRecord& f) {
        return f.type == PictureType::kI;
      }));
  const int p_frames =
      static_cast<int>(std::count_if(frames.begin(), frames.end(), [](const FrameRecord& f) {
        return f.type == PictureType::kP;
      }));
  EXPECT_EQ(i_frames, 3) << "an I frame every 12 frames";
  const int last_skipped = cc.codec == VideoCodec::kH264 ? 0 : 1;
  if ((*reader)->info().b_frame_mvs) {
    EXPECT_GE(total_b_past, 200u);
    EXPECT_GE(total_b_future, 200u);
    EXPECT_EQ(checked_frames, kFrames - i_frames - last_skipped);
  } else {
    EXPECT_EQ(checked_frames, p_frames - last_skipped);
  }
}

INSTANTIATE_TEST_SUITE_P(Codecs, PanTest,
                         ::testing::Values(CodecCase{VideoCodec::kMpeg2, "ts", 2},
                                           CodecCase{VideoCodec::kMpeg4, "avi", 2},
                                           CodecCase{VideoCodec::kMpeg4, "mkv", 4, true},
                                           CodecCase{VideoCodec::kH264, "ts", 4}),
                         [](const auto& info) {
                           return std::string(VideoCodecName(info.param.codec)) +
                                  (info.param.qpel ? "_qpel" : "") + "_" + info.param.ext;
                         });

TEST(MvReaderTest, ByteSourceYieldsTheSameFramesAsTheFile) {
  const std::string path = MakeTempDir("bytes") + "/pan.ts";
  ASSERT_TRUE(WritePan(path, EncoderOptions{}, 17, kVx, kVy).ok());
  auto from_file = MvReader::Open(path);
  ASSERT_TRUE(from_file.ok());
  auto from_bytes =
      MvReader::Open(std::make_unique<MemoryByteSource>(testing::ReadFileBytes(path)));
  ASSERT_TRUE(from_bytes.ok()) << from_bytes.status().ToString();
  Status end_a, end_b;
  const auto a = ReadAll(from_file->get(), &end_a);
  const auto b = ReadAll(from_bytes->get(), &end_b);
  EXPECT_EQ(end_b.code(), StatusCode::kOutOfRange);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].type, b[i].type);
    ASSERT_EQ(a[i].mvs.size(), b[i].mvs.size());
    for (size_t k = 0; k < a[i].mvs.size(); ++k) {
      EXPECT_EQ(a[i].mvs[k].dx_px, b[i].mvs[k].dx_px);
      EXPECT_EQ(a[i].mvs[k].x_px, b[i].mvs[k].x_px);
    }
  }
}

// A byte stream read with a small probe (SessionManagerOptions::reader_probe_bytes)
// gives the same frames, timestamps and stream facts as FFmpeg's default
// probe; the luma is copied only for frames luma_wanted asks for.
TEST(MvReaderTest, SmallProbeSameFramesAndLumaOnlyWhenWanted) {
  const std::string path = MakeTempDir("probe") + "/pan.ts";
  ASSERT_TRUE(WritePan(path, EncoderOptions{}, 25, kVx, kVy).ok());
  const std::string bytes = testing::ReadFileBytes(path);
  MvReaderOptions small;
  small.format = "mpegts";
  small.probe_bytes = 32 << 10;
  small.keep_luma = true;
  int asked = 0;
  small.luma_wanted = [&asked] { return ++asked % 2 == 0; };  // every other frame
  MvReaderOptions full;
  full.format = "mpegts";
  auto a = MvReader::Open(std::make_unique<MemoryByteSource>(bytes), full);
  auto b = MvReader::Open(std::make_unique<MemoryByteSource>(bytes), small);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ((*a)->info().fps, (*b)->info().fps);
  EXPECT_EQ((*a)->info().width_px, (*b)->info().width_px);
  Status end_a, end_b;
  const auto fa = ReadAll(a->get(), &end_a);
  const auto fb = ReadAll(b->get(), &end_b);
  EXPECT_EQ(end_b.code(), StatusCode::kOutOfRange);
  ASSERT_EQ(fa.size(), 25u);
  ASSERT_EQ(fa.size(), fb.size());
  EXPECT_EQ(asked, 25);
  for (size_t i = 0; i < fa.size(); ++i) {
    EXPECT_EQ(fa[i].type, fb[i].type);
    EXPECT_EQ(fa[i].timestamp_s, fb[i].timestamp_s);
    ASSERT_EQ(fa[i].mvs.size(), fb[i].mvs.size());
    EXPECT_TRUE(fa[i].luma.empty());  // keep_luma off
    const size_t plane =
        static_cast<size_t>(b->get()->info().width_px) * b->get()->info().height_px;
    EXPECT_EQ(fb[i].luma.size(), fb[i].index % 2 == 1 ? plane : 0u) << "frame " << fb[i].index;
  }
}

// MbTextureMinEigen on patterns with a known structure tensor: a flat
// block and 1-D stripes (the aperture problem) have lambda_min 0; a sum of
// triangle waves a tri(x) + b tri(y) (slopes +-a, +-b, signs uncorrelated
// over a block) has the mean tensor diag(a^2, b^2), so lambda_min =
// min(a, b)^2; doubling the contrast quadruples it.
TEST(MbTextureTest, KnownTensorsFlatStripesAndTwoDimensionalTexture) {
  constexpr int kW = 64, kH = 48;
  auto tri = [](int v) { return v % 8 < 4 ? v % 8 : 8 - v % 8; };
  auto image = [&](auto intensity) {
    std::vector<uint8_t> img(kW * kH);
    for (int y = 0; y < kH; ++y) {
      for (int x = 0; x < kW; ++x) img[y * kW + x] = static_cast<uint8_t>(intensity(x, y));
    }
    return img;
  };
  const auto flat = image([](int, int) { return 90; });
  const auto stripes = image([&](int x, int) { return 60 + 9 * tri(x); });
  const auto texture = image([&](int x, int y) { return 40 + 3 * tri(x) + 5 * tri(y); });
  const auto texture2 = image([&](int x, int y) { return 40 + 6 * tri(x) + 10 * tri(y); });
  const auto t_flat = MbTextureMinEigen(flat.data(), kW, kW, kH);
  const auto t_stripes = MbTextureMinEigen(stripes.data(), kW, kW, kH);
  const auto t_tex = MbTextureMinEigen(texture.data(), kW, kW, kH);
  const auto t_tex2 = MbTextureMinEigen(texture2.data(), kW, kW, kH);
  ASSERT_EQ(t_flat.size(), static_cast<size_t>(MbCount(kW) * MbCount(kH)));
  for (size_t i = 0; i < t_flat.size(); ++i) {
    EXPECT_EQ(t_flat[i], 0.0f) << i;
    EXPECT_NEAR(t_stripes[i], 0.0f, 1e-6) << i;
  }
  // Interior cells (the border ones clamp their differences at the frame's edge).
  for (int row = 1; row + 1 < MbCount(kH); ++row) {
    for (int col = 1; col + 1 < MbCount(kW); ++col) {
      const size_t i = static_cast<size_t>(row) * MbCount(kW) + col;
      EXPECT_NEAR(t_tex[i], 9.0, 1e-5) << "cell " << col << "," << row;
      EXPECT_NEAR(t_tex2[i], 36.0, 1e-4) << "cell " << col << "," << row;
    }
  }
  // A frame whose size is no multiple of 16: partial cells, no read past the plane.
  const auto partial = MbTextureMinEigen(texture.data(), kW, 40, 20);
  EXPECT_EQ(partial.size(), static_cast<size_t>(MbCount(40) * MbCount(20)));
}

// MbTextureMinEigen against the header's definition, sample by sample, on
// random images of sizes that end inside a cell (1242 = 77 x 16 + 10, 50 =
// 3 x 16 + 2: the last sample x = 49 lies in the partial cell only) or on
// a cell's edge, with a stride wider than the row.
TEST(MbTextureTest, EqualsTheDefinitionOnRandomImagesOfAnySize) {
  std::mt19937 rng(17);
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{
           {1242, 376}, {640, 480}, {50, 37}, {33, 18}, {17, 17}, {3, 3}, {64, 48}}) {
    const int stride = w + 7;
    std::vector<uint8_t> img(static_cast<size_t>(stride) * h);
    for (uint8_t& v : img) v = static_cast<uint8_t>(rng() & 0xFF);
    auto at = [&](int x, int y) {
      return static_cast<int>(img[static_cast<size_t>(y) * stride + x]);
    };
    const std::vector<float> got = MbTextureMinEigen(img.data(), stride, w, h);
    const int cols = MbCount(w), rows = MbCount(h);
    ASSERT_EQ(got.size(), static_cast<size_t>(cols) * rows);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        // Sums of gx^2, gx gy, gy^2 over x = 16 c + 1 + 4 i, y = 16 r + 1 + 4 j
        // inside the cell and the frame; central differences, clamped.
        long long xx = 0, xy = 0, yy = 0, n = 0;
        for (int y = 16 * r + 1; y < std::min(h, 16 * r + 16); y += 4) {
          for (int x = 16 * c + 1; x < std::min(w, 16 * c + 16); x += 4) {
            const int gx = at(std::min(x + 1, w - 1), y) - at(x - 1, y);
            const int gy = at(x, std::min(y + 1, h - 1)) - at(x, y - 1);
            xx += gx * gx;
            xy += gx * gy;
            yy += gy * gy;
            ++n;
          }
        }
        double expected = 0.0;
        if (n > 0) {
          const double scale = 1.0 / (4.0 * static_cast<double>(n));
          const double a = xx * scale, b = xy * scale, d = yy * scale;
          expected = std::max(0.0, 0.5 * (a + d) - std::sqrt(0.25 * (a - d) * (a - d) + b * b));
        }
        EXPECT_FLOAT_EQ(got[static_cast<size_t>(r) * cols + c], static_cast<float>(expected))
            << w << "x" << h << " cell " << c << "," << r;
      }
    }
  }
}

// The reader hands out every anchor's texture on the MB grid (a textured pan:
// median far above a flat block's 0), B frames none, and none when asked not to.
TEST(MvReaderTest, AnchorsCarryTheirMacroblockTexture) {
  const std::string path = MakeTempDir("texture") + "/pan.ts";
  EncoderOptions eo;
  eo.b_frames = 3;
  ASSERT_TRUE(WritePan(path, eo, 13, kVx, kVy).ok());
  for (const bool on : {true, false}) {
    MvReaderOptions options;
    options.mb_texture = on;
    auto reader = MvReader::Open(path, options);
    ASSERT_TRUE(reader.ok());
    Status end;
    const auto frames = ReadAll(reader->get(), &end);
    ASSERT_EQ(frames.size(), 13u);
    const size_t cells = static_cast<size_t>(MbCount((*reader)->info().width_px)) *
                         MbCount((*reader)->info().height_px);
    for (const FrameRecord& f : frames) {
      if (!on || !IsAnchor(f.type)) {
        EXPECT_TRUE(f.mb_texture.empty()) << "frame " << f.index;
        continue;
      }
      ASSERT_EQ(f.mb_texture.size(), cells) << "frame " << f.index;
      std::vector<double> t(f.mb_texture.begin(), f.mb_texture.end());
      EXPECT_GT(Median(t), 1.0) << "frame " << f.index;
    }
  }
}

// reduced_decode (H.264 without its deblocking filter; a no-op for the
// others) changes the decoded pictures only: on a simulated drive (textured
// street, intra and skipped blocks) every frame's type, timing, references
// and every vector field are those of the full decode.
class ReducedDecodeTest : public ::testing::TestWithParam<VideoCodec> {};

TEST_P(ReducedDecodeTest, GivesTheFullDecodesFramesAndVectors) {
  SimulateOptions sim = testing::SmallMpeg2DriveOptions(5, 2.0);
  sim.encoder.codec = GetParam();
  auto drive = testing::SimulateTestDrive("reduced", sim);
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  MvReaderOptions full;
  full.reduced_decode = false;
  MvReaderOptions reduced;
  reduced.reduced_decode = true;
  auto a = MvReader::Open(drive->video_path, full);
  auto b = MvReader::Open(drive->video_path, reduced);
  ASSERT_TRUE(a.ok() && b.ok());
  Status end_a, end_b;
  const auto fa = ReadAll(a->get(), &end_a);
  const auto fb = ReadAll(b->get(), &end_b);
  EXPECT_EQ(end_a.code(), StatusCode::kOutOfRange);
  EXPECT_EQ(end_b.code(), StatusCode::kOutOfRange);
  EXPECT_EQ((*b)->info().width_px, 320);
  EXPECT_EQ((*b)->info().height_px, 240);
  EXPECT_EQ((*a)->info().mv_precision_denom, (*b)->info().mv_precision_denom);
  EXPECT_TRUE((*b)->stats().notes.empty()) << (*b)->stats().notes.front();
  ASSERT_EQ(fa.size(), 60u);
  ASSERT_EQ(fa.size(), fb.size());
  size_t vectors = 0;
  for (size_t i = 0; i < fa.size(); ++i) {
    SCOPED_TRACE("frame " + std::to_string(i));
    EXPECT_EQ(fa[i].index, fb[i].index);
    EXPECT_EQ(fa[i].type, fb[i].type);
    EXPECT_EQ(fa[i].timestamp_s, fb[i].timestamp_s);
    EXPECT_EQ(fa[i].coded_index, fb[i].coded_index);
    EXPECT_EQ(fa[i].prev_anchor_index, fb[i].prev_anchor_index);
    EXPECT_EQ(fa[i].next_anchor_index, fb[i].next_anchor_index);
    EXPECT_EQ(fa[i].reference_certain, fb[i].reference_certain);
    EXPECT_FALSE(fb[i].corrupt);
    ASSERT_EQ(fa[i].mvs.size(), fb[i].mvs.size());
    for (size_t k = 0; k < fa[i].mvs.size(); ++k) {
      const MotionVector &u = fa[i].mvs[k], &v = fb[i].mvs[k];
      ASSERT_TRUE(u.x_px == v.x_px && u.y_px == v.y_px && u.dx_px == v.dx_px &&
                  u.dy_px == v.dy_px && u.w_px == v.w_px && u.h_px == v.h_px &&
                  u.direction == v.direction)
          << "vector " << k;
    }
    vectors += fa[i].mvs.size();
  }
  EXPECT_GT(vectors, 1000u);  // not vacuous: a drive's worth of vectors
}

INSTANTIATE_TEST_SUITE_P(Codecs, ReducedDecodeTest,
                         ::testing::Values(VideoCodec::kMpeg2, VideoCodec::kMpeg4,
                                           VideoCodec::kH264),
                         [](const auto& info) { return std::string(VideoCodecName(info.param)); });

TEST(MvReaderTest, IpppStreamHasOnlyPastVectorsOneFrameApart) {
  const std::string path = MakeTempDir("ippp") + "/ippp.ts";
  EncoderOptions eo;
  eo.codec = VideoCodec::kH264;
  eo.b_frames = 0;
  eo.gop_size = 30;
  eo.quality = 18;
  ASSERT_TRUE(WritePan(path, eo, 12, kVx, kVy).ok());
  auto reader = MvReader::Open(path);
  ASSERT_TRUE(reader.ok());
  Status end;
  const auto frames = ReadAll(reader->get(), &end);
  ASSERT_EQ(frames.size(), 12u);
  EXPECT_EQ((*reader)->info().max_consecutive_b, 0);
  for (size_t i = 1; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].type, PictureType::kP);
    EXPECT_EQ(frames[i].prev_anchor_index, static_cast<int64_t>(i - 1));
    for (const MotionVector& mv : frames[i].mvs) EXPECT_EQ(mv.direction, RefDirection::kPast);
  }
}

// Block geometry: vectors sit on block centres in the pixel-centre convention.
TEST(MvReaderTest, BlockCentresUsePixelCentreConvention) {
  const std::string path = MakeTempDir("centre") + "/pan.ts";
  ASSERT_TRUE(WritePan(path, EncoderOptions{}, 9, kVx, kVy).ok());
  auto reader = MvReader::Open(path);
  ASSERT_TRUE(reader.ok());
  FrameRecord f;
  int seen = 0;
  while ((*reader)->Next(&f).ok()) {
    for (const MotionVector& mv : f.mvs) {
      // MPEG-2 16x16 macroblock (mb_x, mb_y) covers pixels 16*mb_x .. 16*mb_x+15:
      // its centre is 16*mb_x + 7.5.
      ASSERT_EQ(mv.w_px, 16);
      EXPECT_FLOAT_EQ(std::fmod(mv.x_px - 7.5f, 16.0f), 0.0f);
      EXPECT_FLOAT_EQ(std::fmod(mv.y_px - 7.5f, 16.0f), 0.0f);
      ++seen;
    }
  }
  EXPECT_GT(seen, 100);
}

}  // namespace
}  // namespace slapse

namespace slapse {
namespace {

// Encodes testsrc with the ffmpeg CLI: real encoders for codecs slapse must refuse.
std::string EncodeWithCli(const std::string& codec_args, const std::string& name) {
  const std::string path = MakeTempDir("cli") + "/" + name;
  const std::string cmd =
      "ffmpeg -nostdin -v error -f lavfi -i testsrc=size=160x120:rate=10 "
      "-frames:v 5 " +
      codec_args + " -y " + path;
  EXPECT_EQ(testing::RunCommand(cmd), 0) << cmd;
  return path;
}

// Interlaced MPEG-2 (docs/METHOD.md, "MV reader"). An interlaced camera's pan
// (each frame's bottom field half a frame after its top field) coded by
// libavcodec as interlaced frame pictures, field or frame prediction per
// macroblock (+ilme+ildct, top field first). FFmpeg exports a field-predicted
// macroblock as two 16x8 blocks without their reference field; the reader
// drops them and keeps the frame-predicted 16x16 ones, whose displacement is
// the frame's over the anchors' distance.
constexpr double kInterlacedVy = 3.0;  // px per frame: fields 1.5 px apart

TEST(InterlacedMpeg2Test, FieldPredictedVectorsAreDroppedFrameVectorsAreTheFramesMotion) {
  const std::string path = MakeTempDir("interlaced") + "/pan.ts";
  auto eo = EncoderPreset("mpeg2-interlaced", 30.0);
  ASSERT_TRUE(eo.ok());
  eo->quality = 3;
  ASSERT_TRUE(WritePan(path, *eo, kFrames, kVx, kInterlacedVy).ok());

  auto reader = MvReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  Status end;
  const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
  EXPECT_EQ(end.code(), StatusCode::kOutOfRange) << end.ToString();
  ASSERT_EQ(static_cast<int>(frames.size()), kFrames);
  const StreamInfo& info = (*reader)->info();
  const ReadStats& stats = (*reader)->stats();
  EXPECT_TRUE(info.interlaced);
  EXPECT_FALSE(info.field_pictures);
  EXPECT_TRUE(info.reencoded_from.empty());
  EXPECT_EQ(info.max_consecutive_b, 3);
  // The encoder predicts some macroblocks by field: their vectors are dropped, said once.
  EXPECT_GT(stats.field_mvs_dropped, 50);
  ASSERT_FALSE(stats.notes.empty());
  EXPECT_NE(stats.notes[0].find("field-predicted vectors are dropped"), std::string::npos)
      << stats.notes[0];
  // 240 rows are 7.5 field macroblock rows: the padded 16th macroblock row,
  // wholly below the picture, has vectors too; they are dropped.
  EXPECT_GT(stats.outside_mvs_dropped, 0);

  int64_t kept = 0, exact = 0, within_1px = 0;
  for (const FrameRecord& f : frames) {
    for (const MotionVector& mv : f.mvs) {
      ASSERT_EQ(mv.h_px, 16) << "frame " << f.index;
      ASSERT_LT(mv.y_px, 240.0f);
      if (mv.x_px < 40 || mv.x_px > 280 || mv.y_px < 40 || mv.y_px > 200) continue;
      const double gap = mv.direction == RefDirection::kPast
                             ? -static_cast<double>(f.index - f.prev_anchor_index)
                             : static_cast<double>(f.next_anchor_index - f.index);
      const double err = std::hypot(mv.dx_px - gap * kVx, mv.dy_px - gap * kInterlacedVy);
      ++kept;
      exact += err <= 0.5 + 1e-6;
      within_1px += err <= 1.0 + 1e-6;
    }
  }
  ASSERT_GT(kept, 2000);
  // Measured: 2991 kept, 82.0 % within 0.5 px, 98.5 % within 1 px; 8838
  // field-predicted vectors (4419 macroblocks) and 822 outside dropped.
  EXPECT_GE(within_1px, 0.95 * kept) << within_1px << " of " << kept;
  EXPECT_GE(exact, 0.75 * kept) << exact << " of " << kept;
  std::printf(
      "interlaced pan: %lld vectors kept, %.1f %% within 0.5 px, %.1f %% within 1 px; "
      "%lld field-predicted and %lld outside dropped\n",
      static_cast<long long>(kept), 100.0 * exact / kept, 100.0 * within_1px / kept,
      static_cast<long long>(stats.field_mvs_dropped),
      static_cast<long long>(stats.outside_mvs_dropped));
}

// Field pictures (each field its own picture): FFmpeg exports their vectors
// on a frame's macroblock grid with the two fields' rows interleaved, in field
// lines and without their reference field. The reader re-encodes such a stream
// (by default) or refuses it. The stream is spliced from libavcodec's
// intra-coded fields (WriteMpeg2IntraFieldPictures): what FFmpeg decodes as
// field pictures.
TEST(InterlacedMpeg2Test, FieldPicturesAreReencodedOrRefused) {
  const std::string path = MakeTempDir("fields") + "/fields.m2v";
  constexpr int kFieldFrames = 13;
  ASSERT_TRUE(testing::WriteMpeg2IntraFieldPictures(path, kFieldFrames, kVx, kInterlacedVy).ok());
  {
    auto reader = MvReader::Open(path);
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    Status end;
    const std::vector<FrameRecord> frames = ReadAll(reader->get(), &end);
    EXPECT_EQ(end.code(), StatusCode::kOutOfRange) << end.ToString();
    EXPECT_EQ(static_cast<int>(frames.size()), kFieldFrames);
    const StreamInfo& info = (*reader)->info();
    EXPECT_TRUE(info.field_pictures);
    EXPECT_TRUE(info.interlaced);
    EXPECT_EQ(info.reencoded_from, "mpeg2video");
    EXPECT_EQ(info.width_px, 320);
    EXPECT_EQ(info.height_px, 256);
    ASSERT_FALSE((*reader)->stats().notes.empty());
    EXPECT_NE((*reader)->stats().notes[0].find("field pictures"), std::string::npos);
    // The re-encoder's vectors: the pan's motion between the woven frames.
    std::vector<double> p_dx, p_dy;
    for (const FrameRecord& f : frames) {
      if (f.type != PictureType::kP) continue;
      const double gap = static_cast<double>(f.index - f.prev_anchor_index);
      for (const MotionVector& mv : f.mvs) {
        if (mv.x_px < 40 || mv.x_px > 280 || mv.y_px < 40 || mv.y_px > 216) continue;
        p_dx.push_back(mv.dx_px / gap);
        p_dy.push_back(mv.dy_px / gap);
      }
    }
    ASSERT_GE(p_dx.size(), 100u);
    EXPECT_NEAR(Median(p_dx), -kVx, 0.25);
    EXPECT_NEAR(Median(p_dy), -kInterlacedVy, 0.25);
  }
  MvReaderOptions off;
  off.reencode = false;
  auto reader = MvReader::Open(path, off);
  ASSERT_TRUE(reader.ok()) << "field pictures are seen in the first packet, not at opening";
  FrameRecord f;
  const Status s = (*reader)->Next(&f);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition) << s.ToString();
  EXPECT_NE(s.message().find("field pictures"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("re-encoding is off"), std::string::npos) << s.message();
}

class NoMvCodecTest : public ::testing::TestWithParam<std::pair<const char*, const char*>> {};

// With re-encoding off (MvReaderOptions::reencode = false) a codec without
// vectors is refused up front; by default it is re-encoded (every frame comes
// out; vectors checked in codec_test.cc).
TEST_P(NoMvCodecTest, IsReencodedByDefaultAndRefusedUpFrontWhenOff) {
  const auto& [args, name] = GetParam();
  const std::string path = EncodeWithCli(args, name);
  const std::string expected_codec = std::string(name).substr(0, std::string(name).find('.'));
  {
    auto reencoded = MvReader::Open(path);
    ASSERT_TRUE(reencoded.ok()) << reencoded.status().ToString();
    EXPECT_EQ((*reencoded)->info().reencoded_from, expected_codec);
    Status end;
    EXPECT_EQ(ReadAll(reencoded->get(), &end).size(), 5u);
    EXPECT_EQ(end.code(), StatusCode::kOutOfRange) << end.ToString();
  }
  MvReaderOptions off;
  off.reencode = false;
  auto reader = MvReader::Open(path, off);
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kFailedPrecondition);
  const std::string& msg = reader.status().message();
  EXPECT_NE(msg.find("'" + expected_codec + "'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("H.264"), std::string::npos) << "says what to do: " << msg;
}

INSTANTIATE_TEST_SUITE_P(
    Codecs, NoMvCodecTest,
    ::testing::Values(std::make_pair("-c:v libx265 -x265-params log-level=error", "hevc.mkv"),
                      std::make_pair("-c:v libvpx-vp9 -deadline realtime -cpu-used 8", "vp9.webm"),
                      std::make_pair("-c:v libaom-av1 -cpu-used 8 -usage realtime", "av1.mkv")),
    [](const auto& info) {
      std::string n = info.param.second;
      return n.substr(0, n.find('.'));
    });

struct DamagedRun {
  int frames = 0;
  Status end;
};

DamagedRun ReadDamaged(const std::string& bytes, const std::string& ext) {
  const std::string path = MakeTempDir("damaged") + "/damaged." + ext;
  testing::WriteFileBytes(path, bytes);
  DamagedRun run;
  auto reader = MvReader::Open(path);
  if (!reader.ok()) {
    run.end = reader.status();
    return run;
  }
  std::vector<FrameRecord> frames = ReadAll(reader->get(), &run.end);
  run.frames = static_cast<int>(frames.size());
  return run;
}

class DamageTest : public ::testing::TestWithParam<VideoCodec> {};

TEST_P(DamageTest, CorruptMiddleYieldsDecodableFramesAndDataLoss) {
  const std::string path = MakeTempDir("good") + "/good.ts";
  EncoderOptions eo;
  eo.codec = GetParam();
  eo.quality = GetParam() == VideoCodec::kH264 ? 23 : 4;
  ASSERT_TRUE(WritePan(path, eo, 60, kVx, kVy).ok());
  std::string bytes = testing::ReadFileBytes(path);
  // Overwrite the payload of TS packets in the middle third (keep the 4-byte
  // headers so the demuxer still follows the stream): the codec layer breaks.
  uint32_t lcg = 12345;
  for (size_t pkt = bytes.size() / 3 / 188; pkt < bytes.size() / 2 / 188; pkt += 3) {
    for (size_t i = pkt * 188 + 4; i < (pkt + 1) * 188; ++i) {
      lcg = lcg * 1664525u + 1013904223u;
      bytes[i] = static_cast<char>(lcg >> 24);
    }
  }
  const DamagedRun run = ReadDamaged(bytes, "ts");
  EXPECT_EQ(run.end.code(), StatusCode::kDataLoss) << run.end.ToString();
  EXPECT_NE(run.end.message().find("first:"), std::string::npos) << run.end.message();
  EXPECT_GT(run.frames, 20) << "frames before the damage are still yielded";
}

TEST_P(DamageTest, TruncatedStreamYieldsTheFramesBeforeTheCutAndDataLoss) {
  const std::string path = MakeTempDir("good") + "/good.ts";
  EncoderOptions eo;
  eo.codec = GetParam();
  eo.quality = GetParam() == VideoCodec::kH264 ? 23 : 4;
  ASSERT_TRUE(WritePan(path, eo, 60, kVx, kVy).ok());
  const std::string bytes = testing::ReadFileBytes(path);
  // Cut in the middle of a TS packet, as a dropped connection would.
  const DamagedRun run = ReadDamaged(bytes.substr(0, bytes.size() * 3 / 5 + 101), "ts");
  EXPECT_EQ(run.end.code(), StatusCode::kDataLoss) << run.end.ToString();
  EXPECT_GT(run.frames, 20);
  EXPECT_LT(run.frames, 60);
}

INSTANTIATE_TEST_SUITE_P(Codecs, DamageTest,
                         ::testing::Values(VideoCodec::kMpeg2, VideoCodec::kMpeg4,
                                           VideoCodec::kH264),
                         [](const auto& info) { return VideoCodecName(info.param); });

TEST(MvReaderErrors, MissingFileIsNotFound) {
  auto reader = MvReader::Open("/nonexistent/drive.ts");
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kNotFound);
  EXPECT_NE(reader.status().message().find("/nonexistent/drive.ts"), std::string::npos);
}

TEST(MvReaderErrors, GarbageIsInvalidArgument) {
  std::string junk(64 * 1024, '\0');
  uint32_t lcg = 99;
  for (char& c : junk) c = static_cast<char>((lcg = lcg * 1664525u + 1013904223u) >> 24);
  auto reader = MvReader::Open(std::make_unique<MemoryByteSource>(junk));
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kInvalidArgument) << reader.status().ToString();
}

TEST(MvReaderErrors, EmptyInputIsInvalidArgument) {
  auto reader = MvReader::Open(std::make_unique<MemoryByteSource>(""));
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kInvalidArgument) << reader.status().ToString();
}

TEST(MvReaderErrors, InterruptCancelsOpen) {
  const std::string path = MakeTempDir("int") + "/pan.ts";
  ASSERT_TRUE(WritePan(path, EncoderOptions{}, 5, kVx, kVy).ok());
  MvReaderOptions opts;
  opts.interrupt = [] { return true; };
  auto reader = MvReader::Open(path, opts);
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kCancelled) << reader.status().ToString();
}

}  // namespace
}  // namespace slapse

namespace slapse {
namespace {

// FFmpeg does not say which reference an H.264 vector uses: B-pyramids and
// multiple references must be detected and reported, not guessed.
TEST(MvReaderTest, ReportsH264BPyramidAndMultipleReferences) {
  EncoderOptions plain;
  plain.codec = VideoCodec::kH264;
  plain.b_frames = 3;
  plain.gop_size = 24;
  plain.quality = 20;
  EncoderOptions pyramid = plain;
  pyramid.h264_b_pyramid = true;
  pyramid.h264_refs = 3;
  EncoderOptions ippp_refs = plain;
  ippp_refs.b_frames = 0;
  ippp_refs.h264_refs = 3;
  struct Case {
    EncoderOptions opts;
    bool b_pyramid, extra_refs;
  };
  for (const Case& c :
       {Case{plain, false, false}, Case{pyramid, true, true}, Case{ippp_refs, false, true}}) {
    const std::string path = MakeTempDir("pyramid") + "/pan.ts";
    ASSERT_TRUE(WritePan(path, c.opts, 25, kVx, kVy).ok());
    auto reader = MvReader::Open(path);
    ASSERT_TRUE(reader.ok());
    FrameRecord f;
    while ((*reader)->Next(&f).ok()) {
    }
    const StreamInfo& info = (*reader)->info();
    EXPECT_EQ(info.b_pyramid, c.b_pyramid) << "refs " << c.opts.h264_refs;
    EXPECT_EQ(info.extra_references(), c.extra_refs)
        << "max_ref_frames " << info.max_ref_frames << ", n_B " << info.max_consecutive_b;
  }
}

}  // namespace
}  // namespace slapse
