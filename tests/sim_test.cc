// Street simulator: determinism per seed, exact projection (edges land where
// Intrinsics::Project puts them), ground truth consistent with the pixels
// (plane-induced warps between frames), ground-truth files round trip, the
// camera path's speed and vibration, label sanity, and an end-to-end drive.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/common/angles.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/camera_path.h"
#include "lab/sim/centreline.h"
#include "lab/sim/renderer.h"
#include "lab/sim/scene.h"
#include "lab/sim/simulate.h"

namespace slapse {
namespace {

const double kDeg = DegToRad(1.0);

std::string TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("slapse_sim_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  return dir.string();
}

bool SamePlanes(const std::vector<GtPlane>& a, const std::vector<GtPlane>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].id != b[i].id || a[i].kind != b[i].kind || a[i].normal_world != b[i].normal_world ||
        a[i].distance_m != b[i].distance_m ||
        a[i].polygons_world.size() != b[i].polygons_world.size()) {
      return false;
    }
    for (size_t j = 0; j < a[i].polygons_world.size(); ++j) {
      if (a[i].polygons_world[j] != b[i].polygons_world[j]) return false;
    }
  }
  return true;
}

TEST(CentrelineTest, ContinuousAndProjectsBack) {
  Centreline cl;
  cl.AddStraight(30.0);
  cl.AddArc(20.0, 1.0 / 30.0);
  cl.AddStraight(25.0);
  cl.AddArc(15.0, -1.0 / 40.0);
  cl.AddStraight(10.0);
  EXPECT_DOUBLE_EQ(cl.length_m(), 100.0);
  for (const auto& seg : cl.segments()) {
    const double s = seg.s0_m;
    EXPECT_LT((cl.Point(s - 1e-7) - cl.Point(s + 1e-7)).norm(), 1e-6);
    EXPECT_NEAR(cl.Heading(s - 1e-7), cl.Heading(s + 1e-7), 1e-7);
  }
  // The arc turns by length * curvature.
  EXPECT_NEAR(cl.Heading(60.0) - cl.Heading(0.0), 20.0 / 30.0, 1e-12);
  for (double s = -5.0; s < 105.0; s += 3.7) {
    for (double l : {-9.0, -2.5, 0.0, 4.0, 11.0}) {
      double s2, l2;
      cl.Project(cl.Offset(s, l), &s2, &l2);
      EXPECT_NEAR(s2, s, 1e-9) << "s " << s << " l " << l;
      EXPECT_NEAR(l2, l, 1e-9) << "s " << s << " l " << l;
    }
  }
  // Heading integral: derivative is the heading.
  for (double s : {10.0, 40.0, 74.0}) {
    EXPECT_NEAR((cl.HeadingIntegral(s + 1e-4) - cl.HeadingIntegral(s - 1e-4)) / 2e-4, cl.Heading(s),
                1e-7);
  }
}

TEST(SceneTest, DeterministicPerSeedAndConsistent) {
  SceneOptions o;
  o.seed = 3;
  o.length_m = 300.0;
  auto a = GenerateStreetScene(o);
  auto b = GenerateStreetScene(o);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok());
  EXPECT_TRUE(SamePlanes(a->planes, b->planes));
  EXPECT_EQ(a->surfaces.size(), b->surfaces.size());
  o.seed = 4;
  auto c = GenerateStreetScene(o);
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(SamePlanes(a->planes, c->planes));

  const Scene& sc = *a;
  ASSERT_GE(sc.planes.size(), 20u);
  EXPECT_EQ(sc.planes[0].kind, PlaneKind::kRoad);
  EXPECT_EQ(sc.planes[0].normal_world, Eigen::Vector3d::UnitZ());
  int facades = 0, backgrounds = 0;
  for (size_t i = 0; i < sc.planes.size(); ++i) {
    const GtPlane& p = sc.planes[i];
    EXPECT_EQ(p.id, static_cast<int>(i));
    EXPECT_NEAR(p.normal_world.norm(), 1.0, 1e-12);
    ASSERT_FALSE(p.polygons_world.empty());
    for (const auto& poly : p.polygons_world) {
      ASSERT_GE(poly.size(), 3u);
      for (const auto& x : poly) EXPECT_NEAR(p.normal_world.dot(x), p.distance_m, 1e-9);
    }
    if (p.kind == PlaneKind::kFacade) {
      ++facades;
      EXPECT_NEAR(p.normal_world.z(), 0.0, 1e-12);  // vertical
    }
    backgrounds += p.kind == PlaneKind::kBackground;
  }
  EXPECT_GE(facades, 20);
  EXPECT_GE(backgrounds, 1);
  // Surfaces carry a right-handed texture frame: u x v = -normal.
  for (const Surface& s : sc.surfaces) {
    if (s.label < 0) continue;
    EXPECT_LT((s.u_axis_world.cross(s.v_axis_world) + sc.planes[s.label].normal_world).norm(),
              1e-9);
  }
}

TEST(SceneTest, RejectsBadOptions) {
  SceneOptions o;
  o.length_m = -1;
  EXPECT_EQ(GenerateStreetScene(o).status().code(), StatusCode::kInvalidArgument);
  o = SceneOptions();
  o.bend_radius_min_m = 5;
  EXPECT_EQ(GenerateStreetScene(o).status().code(), StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------- projection

// A camera at a generic pose and a scene built in its frame: a light wall at
// 12 m and a 2 m square, rotated 10 degrees about the optical axis, at 5 m.
struct EdgeScene {
  Scene scene;
  Rigid3d world_from_cam;
  Eigen::Vector3d corners_cam[4];  // square corners in the camera frame
};

int UniformTexture(Scene* scene, uint8_t grey, double texel_m = 0.05) {
  TextureDesc t;
  t.kind = TextureKind::kChecker;
  t.checker_dark = t.checker_light = cv::Vec3b(grey, grey, grey);
  t.texel_m = texel_m;
  return scene->AddTexture(t);
}

// Adds a plane through `centre_cam` spanned by unit u, v (camera frame), facing the camera.
int AddCamPlane(EdgeScene* es, const Eigen::Vector3d& centre_cam, const Eigen::Vector3d& u_cam,
                const Eigen::Vector3d& v_cam, double half_u, double half_v, int texture) {
  const Rigid3d& T = es->world_from_cam;
  const Eigen::Vector3d origin_cam = centre_cam - half_u * u_cam - half_v * v_cam;
  std::vector<Eigen::Vector3d> poly = {T * origin_cam, T * (origin_cam + 2 * half_u * u_cam),
                                       T * (origin_cam + 2 * half_u * u_cam + 2 * half_v * v_cam),
                                       T * (origin_cam + 2 * half_v * v_cam)};
  const Eigen::Vector3d n = T.rotation * (-u_cam.cross(v_cam));
  return es->scene.AddPlane(PlaneKind::kFacade, n, {poly}, T * origin_cam, T.rotation * u_cam,
                            T.rotation * v_cam, texture);
}

EdgeScene MakeEdgeScene(int square_texture) {
  EdgeScene es;
  es.world_from_cam =
      Rigid3d(WorldFromCamRotation(0.3, 4.0 * kDeg, 1.5 * kDeg), Eigen::Vector3d(3.0, -2.0, 1.4));
  const int light = UniformTexture(&es.scene, 235);
  AddCamPlane(&es, {0, 0, 12}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 30, 30, light);
  const double a = 10.0 * kDeg;
  const Eigen::Vector3d u(std::cos(a), std::sin(a), 0), v(-std::sin(a), std::cos(a), 0);
  const Eigen::Vector3d c(0.3, -0.2, 5.0);
  const int tex = square_texture >= 0 ? square_texture : UniformTexture(&es.scene, 20);
  AddCamPlane(&es, c, u, v, 1.0, 1.0, tex);
  es.corners_cam[0] = c - u - v;
  es.corners_cam[1] = c + u - v;
  es.corners_cam[2] = c + u + v;
  es.corners_cam[3] = c - u + v;
  return es;
}

// Signed offsets (pixels, per image row) between a near-vertical edge found in
// `grey` and the line a-b: the edge position comes from the area the dark side
// covers in a window of the row, which is exact for a box-filtered image.
std::vector<double> EdgeOffsets(const cv::Mat1f& grey, const Eigen::Vector2d& a,
                                const Eigen::Vector2d& b, float dark, float light,
                                int half_window) {
  std::vector<double> out;
  const double ylo = std::min(a.y(), b.y()), yhi = std::max(a.y(), b.y());
  const double margin = 0.2 * (yhi - ylo);
  for (int y = static_cast<int>(std::ceil(ylo + margin)); y <= yhi - margin; ++y) {
    const double x_line = a.x() + (y - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
    const int xc = static_cast<int>(std::lround(x_line));
    const int xa = xc - half_window, xb = xc + half_window;
    if (xa < 0 || xb >= grey.cols || y < 0 || y >= grey.rows) continue;
    // Which side is dark: look at the window ends.
    const bool dark_right = std::abs(grey(y, xb) - dark) < std::abs(grey(y, xa) - dark);
    double covered = 0.0;  // pixels of the dark side inside [xa - 0.5, xb + 0.5]
    for (int x = xa; x <= xb; ++x) covered += (light - grey(y, x)) / (light - dark);
    const double x_edge = dark_right ? xb + 0.5 - covered : xa - 0.5 + covered;
    out.push_back(x_edge - x_line);
  }
  return out;
}

void ExpectEdgesOnProjection(const cv::Mat& bgr, const Eigen::Vector2d* px, double tol_row,
                             double tol_mean, const std::string& what) {
  cv::Mat1f grey;
  cv::Mat g8;
  cv::cvtColor(bgr, g8, cv::COLOR_BGR2GRAY);
  g8.convertTo(grey, CV_32F);
  cv::Mat1f grey_t = grey.t();
  for (int e = 0; e < 4; ++e) {
    Eigen::Vector2d a = px[e], b = px[(e + 1) % 4];
    const bool vertical = std::abs(b.y() - a.y()) > std::abs(b.x() - a.x());
    const cv::Mat1f& img = vertical ? grey : grey_t;
    if (!vertical) {
      a = Eigen::Vector2d(a.y(), a.x());
      b = Eigen::Vector2d(b.y(), b.x());
    }
    const std::vector<double> off = EdgeOffsets(img, a, b, 20.0f, 235.0f, 6);
    ASSERT_GE(off.size(), 20u) << what << " edge " << e;
    double mean = 0.0, worst = 0.0;
    for (double d : off) {
      mean += d / off.size();
      worst = std::max(worst, std::abs(d));
    }
    EXPECT_LT(std::abs(mean), tol_mean) << what << " edge " << e;
    EXPECT_LT(worst, tol_row) << what << " edge " << e;
  }
}

TEST(RendererTest, PolygonEdgesLandOnTheProjection) {
  const Intrinsics k = Intrinsics::FromHorizontalFov(640, 480, 70.0);
  for (int ss : {1, 2, 3}) {
    EdgeScene es = MakeEdgeScene(-1);
    RenderOptions ro;
    ro.supersampling = ss;
    auto frame = RenderFrame(es.scene, k, es.world_from_cam, ro);
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    Eigen::Vector2d px[4];
    for (int c = 0; c < 4; ++c) px[c] = k.Project(es.corners_cam[c]);
    // Per row, the edge is resolved to 1/ss of a pixel; the mean is exact.
    ExpectEdgesOnProjection(frame->bgr, px, 0.5 / ss + 0.02, ss == 1 ? 0.06 : 0.03,
                            "ss=" + std::to_string(ss));
    // The corner itself: the four pixels around it split dark/light as the
    // square covers them, and the label image agrees inside and outside.
    const Eigen::Vector2d c0 = px[0];
    const Eigen::Vector2d inward = (0.5 * (px[1] + px[3]) - c0).normalized();
    const Eigen::Vector2d in = c0 + 4.0 * inward, out = c0 - 4.0 * inward;
    EXPECT_EQ(frame->labels.at<int>(std::lround(in.y()), std::lround(in.x())), 1);
    EXPECT_EQ(frame->labels.at<int>(std::lround(out.y()), std::lround(out.x())), 0);
    const cv::Vec3b dark = frame->bgr.at<cv::Vec3b>(std::lround(in.y()), std::lround(in.x()));
    EXPECT_EQ(dark[1], 20);
  }
}

TEST(RendererTest, TextureEdgesLandOnTheProjection) {
  // A checker texture (0.5 m squares, 2 cm texels: magnified) on the square:
  // its internal edges must also project exactly.
  const Intrinsics k = Intrinsics::FromHorizontalFov(640, 480, 70.0);
  EdgeScene probe = MakeEdgeScene(-1);
  TextureDesc t;
  t.kind = TextureKind::kChecker;
  t.checker_m = 0.5;
  t.texel_m = 0.02;
  t.checker_dark = cv::Vec3b(20, 20, 20);
  t.checker_light = cv::Vec3b(235, 235, 235);
  Scene scene = probe.scene;  // same planes; swap the square's texture
  const int tex = scene.AddTexture(t);
  scene.surfaces[1].texture = tex;
  auto frame = RenderFrame(scene, k, probe.world_from_cam);
  ASSERT_TRUE(frame.ok());
  // Square corner c0 is the texture origin; checker edges at u = 0.5, 1.0, 1.5 m
  // run along v. Test them within one checker row (v in [0.5, 1.0] m) where
  // the colours on both sides are uniform.
  const Eigen::Vector3d c0 = probe.corners_cam[0];
  const Eigen::Vector3d u = (probe.corners_cam[1] - c0) / 2.0;
  const Eigen::Vector3d v = (probe.corners_cam[3] - c0) / 2.0;
  cv::Mat1f grey;
  cv::Mat g8;
  cv::cvtColor(frame->bgr, g8, cv::COLOR_BGR2GRAY);
  g8.convertTo(grey, CV_32F);
  for (double ue : {0.5, 1.0, 1.5}) {
    const Eigen::Vector2d a = k.Project(c0 + ue * u + 0.5 * v);
    const Eigen::Vector2d b = k.Project(c0 + ue * u + 1.0 * v);
    const std::vector<double> off = EdgeOffsets(grey, a, b, 20.0f, 235.0f, 8);
    ASSERT_GE(off.size(), 20u);
    double mean = 0.0, worst = 0.0;
    for (double d : off) {
      mean += d / off.size();
      worst = std::max(worst, std::abs(d));
    }
    EXPECT_LT(std::abs(mean), 0.05) << "u = " << ue;
    EXPECT_LT(worst, 0.2) << "u = " << ue;
  }
}

// ---------------------------------------------------------------- drives

SimulateOptions ShortDrive(uint64_t seed) {
  SimulateOptions o;
  o.seed = seed;
  o.duration_s = 10.0;
  return o;
}

TEST(RendererTest, DeterministicPerSeedAndIndependentOfHistory) {
  auto a = PrepareDrive(ShortDrive(5));
  auto b = PrepareDrive(ShortDrive(5));
  auto c = PrepareDrive(ShortDrive(6));
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_TRUE(SamePlanes(a->scene.planes, b->scene.planes));
  const auto fa = RenderFrame(a->scene, a->intrinsics, a->path.world_from_cam[0]);
  const auto fb = RenderFrame(b->scene, b->intrinsics, b->path.world_from_cam[0]);
  const auto fc = RenderFrame(c->scene, c->intrinsics, c->path.world_from_cam[0]);
  ASSERT_TRUE(fa.ok() && fb.ok() && fc.ok());
  EXPECT_EQ(cv::norm(fa->bgr, fb->bgr, cv::NORM_INF), 0.0);
  EXPECT_EQ(fa->mb_labels, fb->mb_labels);
  EXPECT_GT(cv::norm(fa->bgr, fc->bgr, cv::NORM_L1) / fa->bgr.total(), 10.0);

  // Frame 12 rendered after frames 0..11 equals frame 12 rendered alone.
  auto renderer = Renderer::Create(a->scene, a->intrinsics);
  ASSERT_TRUE(renderer.ok());
  RenderedFrame seq;
  for (int i = 0; i <= 12; i += 3)
    ASSERT_TRUE((*renderer)->Render(a->path.world_from_cam[i], &seq).ok());
  const auto alone = RenderFrame(a->scene, a->intrinsics, a->path.world_from_cam[12]);
  ASSERT_TRUE(alone.ok());
  EXPECT_EQ(cv::norm(seq.bgr, alone->bgr, cv::NORM_INF), 0.0);
}

TEST(CameraPathTest, SpeedHeightAndVibrationStayInRange) {
  for (uint64_t seed : {1, 2, 3}) {
    auto d = PrepareDrive(ShortDrive(seed));
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    const CameraPath& p = d->path;
    ASSERT_EQ(p.world_from_cam.size(), 300u);
    EXPECT_DOUBLE_EQ(p.timestamps_s[1], 1.0 / 30.0);
    EXPECT_GE(p.camera_height_m, 1.3);
    EXPECT_LE(p.camera_height_m, 1.6);
    EXPECT_GE(p.pitch_down_deg, 2.0);
    EXPECT_LE(p.pitch_down_deg, 5.0);
    double prev_yaw = 0.0, prev_rate = 0.0, max_bounce_m = 0.0;
    for (size_t i = 0; i < p.world_from_cam.size(); ++i) {
      const Rigid3d& T = p.world_from_cam[i];
      // The mean height plus the suspension's bounce (PathOptions::bounce_m).
      EXPECT_NEAR(T.translation.z(), p.camera_height_m, PathOptions().bounce_m + 1e-12);
      max_bounce_m = std::max(max_bounce_m, std::abs(T.translation.z() - p.camera_height_m));
      if (i > 0) {
        const double v = (T.translation - p.world_from_cam[i - 1].translation).norm() * 30.0;
        EXPECT_GE(v, 25.0 / 3.6) << "frame " << i;
        EXPECT_LE(v, 50.0 / 3.6) << "frame " << i;
      }
      // Optical axis elevation and roll (camera x axis tilt) in the world.
      const Eigen::Matrix3d R = T.R();
      const double pitch_down = std::asin(-R(2, 2)) / kDeg;
      const double roll = std::asin(-R(2, 0)) / kDeg;
      EXPECT_NEAR(pitch_down, p.pitch_down_deg, 0.5) << "frame " << i;
      EXPECT_LT(std::abs(roll), 0.5) << "frame " << i;
      // The camera stays in the right lane and looks along it.
      double s, l;
      d->scene.centreline.Project(T.translation.head<2>(), &s, &l);
      EXPECT_NEAR(l, d->scene.lane_offset_m, 1e-6);
      const double yaw = std::atan2(R(1, 2), R(0, 2));
      const double lane_heading = d->scene.centreline.Heading(s);
      EXPECT_LT(std::abs(std::remainder(yaw - lane_heading, 2 * M_PI)), 3.0 * kDeg);
      // Yaw rate: bounded (R >= 25 m at <= 50 km/h) and without jumps.
      const double rate = std::remainder(yaw - prev_yaw, 2 * M_PI);
      if (i > 0) {
        EXPECT_LT(std::abs(rate), 1.2 * kDeg) << "frame " << i;
      }
      if (i > 1) {
        EXPECT_LT(std::abs(rate - prev_rate), 0.1 * kDeg) << "frame " << i;
      }
      prev_yaw = yaw;
      prev_rate = rate;
    }
    // It does bounce: within 10 s the sum of three sinusoids nears its peak.
    EXPECT_GT(max_bounce_m, 0.3 * PathOptions().bounce_m);
    EXPECT_GT(p.distance_m, 25.0 / 3.6 * 9.9);
    EXPECT_LT(p.distance_m, 50.0 / 3.6 * 10.0);
  }
}

TEST(RendererTest, LabelsAreSane) {
  auto d = PrepareDrive(ShortDrive(1));
  ASSERT_TRUE(d.ok());
  auto f = RenderFrame(d->scene, d->intrinsics, d->path.world_from_cam[0]);
  ASSERT_TRUE(f.ok());
  ASSERT_EQ(f->mb_cols, 40);
  ASSERT_EQ(f->mb_rows, 30);
  ASSERT_EQ(f->mb_labels.size(), 1200u);
  // Road right in front, sky somewhere along the top row.
  EXPECT_EQ(f->mb_labels[29 * 40 + 20], 0);
  EXPECT_EQ(f->mb_labels[29 * 40 + 19], 0);
  bool sky = false;
  for (int c = 0; c < 40; ++c) sky = sky || f->mb_labels[c] == kMbSky;
  EXPECT_TRUE(sky);
  // A plane label means the plane covers (nearly) the whole block.
  int planes = 0;
  for (int r = 0; r < 30; ++r) {
    for (int c = 0; c < 40; ++c) {
      const int l = f->mb_labels[r * 40 + c];
      if (l < 0) continue;
      ++planes;
      int n = 0;
      for (int y = 16 * r; y < 16 * r + 16; ++y) {
        for (int x = 16 * c; x < 16 * c + 16; ++x) n += f->labels.at<int>(y, x) == l;
      }
      EXPECT_GE(n, 220) << "block " << c << "," << r;
    }
  }
  EXPECT_GT(planes, 600);  // most of a street view is planar
  // Mixed blocks list what their samples see: largest share first, summing
  // to 1, no label reaching the coverage; the pixels agree.
  int mixed = 0;
  for (int mb = 0; mb < 1200; ++mb) {
    const auto it = f->mb_mixed_shares.find(mb);
    if (f->mb_labels[mb] != kMbMixed) {
      EXPECT_EQ(it, f->mb_mixed_shares.end()) << mb;
      continue;
    }
    ++mixed;
    ASSERT_NE(it, f->mb_mixed_shares.end()) << mb;
    ASSERT_GE(it->second.size(), 2u);
    double sum = 0;
    for (size_t k = 0; k < it->second.size(); ++k) {
      sum += it->second[k].share;
      if (k > 0) EXPECT_LE(it->second[k].share, it->second[k - 1].share);
    }
    EXPECT_NEAR(sum, 1.0, 1e-5);
    EXPECT_LT(it->second[0].share, kMbLabelCoverage);
    int n = 0;  // output pixels whose majority label is the block's largest
    for (int y = 16 * (mb / 40); y < 16 * (mb / 40) + 16; ++y) {
      for (int x = 16 * (mb % 40); x < 16 * (mb % 40) + 16; ++x) {
        n += f->labels.at<int>(y, x) == it->second[0].label;
      }
    }
    EXPECT_NEAR(n / 256.0, it->second[0].share, 0.1) << mb;
  }
  EXPECT_GT(mixed, 20);
}

// Ground truth vs pixels: map every pixel of plane-labelled blocks of frame
// j through its plane into frame i (the plane-induced homography) and compare
// intensities. The mean absolute difference, as a function of an extra shift
// of the warp, must be smallest at zero shift, to within a few hundredths of
// a pixel: a wrong pose, plane, or pixel convention moves the minimum.
TEST(RendererTest, PlaneWarpsBetweenFramesMatchThePixels) {
  auto d = PrepareDrive(ShortDrive(2));
  ASSERT_TRUE(d.ok());
  auto renderer = Renderer::Create(d->scene, d->intrinsics);
  ASSERT_TRUE(renderer.ok());
  const int fi = 40, fj = 43;
  RenderedFrame a, b;
  ASSERT_TRUE((*renderer)->Render(d->path.world_from_cam[fi], &a).ok());
  ASSERT_TRUE((*renderer)->Render(d->path.world_from_cam[fj], &b).ok());
  cv::Mat1f ga, gb;
  cv::Mat tmp;
  cv::cvtColor(a.bgr, tmp, cv::COLOR_BGR2GRAY);
  tmp.convertTo(ga, CV_32F);
  cv::cvtColor(b.bgr, tmp, cv::COLOR_BGR2GRAY);
  tmp.convertTo(gb, CV_32F);
  const Intrinsics& k = d->intrinsics;
  const Rigid3d& wj = d->path.world_from_cam[fj];
  const Rigid3d ci = d->path.world_from_cam[fi].Inverse();
  // Correspondences: pixel of frame j -> its position in frame i.
  std::vector<std::pair<cv::Point, Eigen::Vector2d>> matches;
  for (int r = 0; r < b.mb_rows; ++r) {
    for (int c = 0; c < b.mb_cols; ++c) {
      const int label = b.mb_labels[r * b.mb_cols + c];
      if (label < 0) continue;
      const GtPlane& plane = d->scene.planes[label];
      for (int y = 16 * r + 2; y < 16 * r + 14; ++y) {
        for (int x = 16 * c + 2; x < 16 * c + 14; ++x) {
          if (b.labels.at<int>(y, x) != label) continue;
          const Eigen::Vector3d ray = wj.rotation * k.Unproject(Eigen::Vector2d(x, y));
          const double t = (plane.distance_m - plane.normal_world.dot(wj.translation)) /
                           plane.normal_world.dot(ray);
          const Eigen::Vector2d p = k.Project(ci * (wj.translation + t * ray));
          const int xi = static_cast<int>(std::lround(p.x()));
          const int yi = static_cast<int>(std::lround(p.y()));
          if (xi < 2 || yi < 2 || xi >= k.width_px - 3 || yi >= k.height_px - 3) continue;
          if (a.labels.at<int>(yi, xi) != label) continue;  // occluded in frame i
          matches.emplace_back(cv::Point(x, y), p);
        }
      }
    }
  }
  ASSERT_GT(matches.size(), 50000u);
  auto mad = [&](double dx, double dy) {
    double sum = 0.0;
    for (const auto& [q, p] : matches) {
      cv::Mat patch;
      cv::getRectSubPix(ga, cv::Size(1, 1), cv::Point2f(p.x() + dx, p.y() + dy), patch);
      sum += std::abs(patch.at<float>(0, 0) - gb(q.y, q.x));
    }
    return sum / matches.size();
  };
  const double h = 0.15;
  const double m0 = mad(0, 0);
  const double mxm = mad(-h, 0), mxp = mad(h, 0), mym = mad(0, -h), myp = mad(0, h);
  EXPECT_LT(m0, 6.0) << "resampling noise only";
  EXPECT_LT(m0, std::min({mxm, mxp, mym, myp}));
  // Vertex of the parabola through the three samples along each axis.
  const double vx = h * (mxm - mxp) / (2.0 * (mxm - 2.0 * m0 + mxp));
  const double vy = h * (mym - myp) / (2.0 * (mym - 2.0 * m0 + myp));
  EXPECT_LT(std::abs(vx), 0.03);
  EXPECT_LT(std::abs(vy), 0.03);
  EXPECT_GT(mad(1.5, 0), 1.8 * m0) << "the texture must be rich enough to localise";
}

TEST(GroundTruthTest, SaveLoadRoundTrip) {
  GroundTruth gt;
  gt.intrinsics = Intrinsics::FromHorizontalFov(640, 480, 70.0);
  gt.fps = 30.0;
  gt.mb_cols = 40;
  gt.mb_rows = 30;
  GtPlane road;
  road.id = 0;
  road.kind = PlaneKind::kRoad;
  road.polygons_world = {{{0, 0, 0}, {10, 0, 0}, {10, 5, 0}},
                         {{-1e-5, 3.25, 0}, {1, 2, 0}, {2, 2, 0}}};
  GtPlane wall;
  wall.id = 1;
  wall.kind = PlaneKind::kFacade;
  wall.normal_world = Eigen::Vector3d(0.6, -0.8, 0.0);
  wall.distance_m = -7.123456789012345;
  wall.polygons_world = {{{1, 2, 3}, {4, 5, 6}, {7, 8, 9.5}, {1.0 / 3.0, 2, 0}}};
  GtPlane bg;
  bg.id = 2;
  bg.kind = PlaneKind::kBackground;
  gt.planes = {road, wall, bg};
  for (int i = 0; i < 3; ++i) {
    GtFrame f;
    f.timestamp_s = i / 30.0;
    f.world_from_cam = Rigid3d(
        Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * i + 0.2, Eigen::Vector3d(1, 2, 3).normalized())),
        Eigen::Vector3d(i * 0.4, -1.0 / 7.0, 1.5));
    f.mb_labels.resize(1200);
    for (int m = 0; m < 1200; ++m) f.mb_labels[m] = (m * 7 + i) % 6 - 3;
    for (int m = 0; m < 1200; ++m) {
      if (f.mb_labels[m] == kMbMixed && m % 5 != 0) {
        f.mixed_shares[m] = {{m % 3, 0.625f}, {kMbSky, 0.25f}, {kMbClutter, 0.125f}};
      }
    }
    gt.frames.push_back(f);
  }
  const std::string dir = TempDir("gt");
  ASSERT_TRUE(SaveGroundTruth(gt, dir).ok());
  for (const char* name :
       {"trajectory_tum.txt", "intrinsics.json", "planes.json", "mb_labels.txt", "meta.json"}) {
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / name)) << name;
  }
  auto back = LoadGroundTruth(dir);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->intrinsics.fx_px, gt.intrinsics.fx_px);
  EXPECT_EQ(back->intrinsics.cx_px, gt.intrinsics.cx_px);
  EXPECT_EQ(back->intrinsics.width_px, 640);
  EXPECT_EQ(back->intrinsics.height_px, 480);
  EXPECT_EQ(back->fps, 30.0);
  EXPECT_EQ(back->mb_cols, 40);
  EXPECT_EQ(back->mb_rows, 30);
  EXPECT_TRUE(SamePlanes(back->planes, gt.planes));
  ASSERT_EQ(back->frames.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(back->frames[i].timestamp_s, gt.frames[i].timestamp_s);
    EXPECT_EQ(back->frames[i].world_from_cam.translation, gt.frames[i].world_from_cam.translation);
    EXPECT_EQ(back->frames[i].world_from_cam.rotation.coeffs(),
              gt.frames[i].world_from_cam.rotation.coeffs());
    EXPECT_EQ(back->frames[i].mb_labels, gt.frames[i].mb_labels);
    ASSERT_EQ(back->frames[i].mixed_shares.size(), gt.frames[i].mixed_shares.size());
    for (const auto& [mb, shares] : gt.frames[i].mixed_shares) {
      const auto it = back->frames[i].mixed_shares.find(mb);
      ASSERT_NE(it, back->frames[i].mixed_shares.end()) << mb;
      ASSERT_EQ(it->second.size(), shares.size());
      for (size_t k = 0; k < shares.size(); ++k) {
        EXPECT_EQ(it->second[k].label, shares[k].label);
        EXPECT_EQ(it->second[k].share, shares[k].share);
      }
    }
  }
  // LabelAt: pixel centres on integers, 16 pixels a block.
  EXPECT_EQ(back->LabelAt(1, 0.0, 0.0), gt.frames[1].mb_labels[0]);
  EXPECT_EQ(back->LabelAt(1, 15.4, 15.4), gt.frames[1].mb_labels[0]);
  EXPECT_EQ(back->LabelAt(1, 15.6, 0.0), gt.frames[1].mb_labels[1]);
  EXPECT_EQ(back->LabelAt(2, 639.0, 479.0), gt.frames[2].mb_labels[1199]);
  EXPECT_EQ(back->LabelAt(2, 700.0, 10.0), kMbMixed);
  EXPECT_EQ(back->LabelAt(5, 10.0, 10.0), kMbMixed);
  EXPECT_STREQ(PlaneKindName(PlaneKind::kBackground), "background");
  // Missing or corrupt files are errors, not crashes.
  // The shares are optional (older drives); a corrupt line is an error.
  const auto mixed = std::filesystem::path(dir) / "mb_mixed.txt";
  { std::ofstream(mixed, std::ios::app) << "1 12 0:1.5\n"; }
  EXPECT_EQ(LoadGroundTruth(dir).status().code(), StatusCode::kDataLoss);
  std::filesystem::remove(mixed);
  auto without = LoadGroundTruth(dir);
  ASSERT_TRUE(without.ok()) << without.status().ToString();
  EXPECT_TRUE(without->frames[1].mixed_shares.empty());
  std::filesystem::remove(std::filesystem::path(dir) / "planes.json");
  EXPECT_EQ(LoadGroundTruth(dir).status().code(), StatusCode::kNotFound);
  std::filesystem::remove_all(dir);
}

TEST(SimulateTest, WritesVideoAndGroundTruth) {
  SimulateOptions o;
  o.seed = 9;
  o.duration_s = 0.5;
  o.width_px = 320;
  o.height_px = 240;
  o.output_dir = TempDir("drive");
  SimulateReport report;
  const Status s = SimulateDrive(o, &report);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(report.frames, 15);
  EXPECT_GT(report.distance_m, 0.5 * 25.0 / 3.6 * 0.9);
  EXPECT_GT(std::filesystem::file_size(report.video_path), 1000u);
  auto gt = LoadGroundTruth(o.output_dir);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  EXPECT_EQ(gt->frames.size(), 15u);
  EXPECT_EQ(gt->mb_cols, 20);
  EXPECT_EQ(gt->mb_rows, 15);
  EXPECT_EQ(gt->fps, 30.0);
  EXPECT_EQ(static_cast<int>(gt->planes.size()), report.num_planes);
  EXPECT_EQ(gt->LabelAt(0, 160, 235), 0);  // road in front
  std::filesystem::remove_all(o.output_dir);
}

}  // namespace
}  // namespace slapse
