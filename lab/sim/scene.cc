#include "lab/sim/scene.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/common/angles.h"
#include "lab/sim/random.h"

namespace slapse {

int Scene::AddTexture(const TextureDesc& desc) {
  textures.push_back(desc);
  return static_cast<int>(textures.size()) - 1;
}

int Scene::AddPlane(PlaneKind kind, const Eigen::Vector3d& normal_world,
                    const std::vector<std::vector<Eigen::Vector3d>>& polygons_world,
                    const Eigen::Vector3d& origin_world, const Eigen::Vector3d& u_axis_world,
                    const Eigen::Vector3d& v_axis_world, int texture) {
  GtPlane plane;
  plane.id = static_cast<int>(planes.size());
  plane.kind = kind;
  plane.normal_world = normal_world;
  plane.distance_m = normal_world.dot(origin_world);
  plane.polygons_world = polygons_world;
  planes.push_back(plane);
  Surface surface;
  surface.label = plane.id;
  surface.texture = texture;
  surface.origin_world = origin_world;
  surface.u_axis_world = u_axis_world;
  surface.v_axis_world = v_axis_world;
  surface.polygons_world = polygons_world;
  surfaces.push_back(surface);
  return plane.id;
}

const char* SceneKindName(SceneKind kind) {
  switch (kind) {
    case SceneKind::kUrban:
      return "urban";
    case SceneKind::kAvenue:
      return "avenue";
    case SceneKind::kRural:
      return "rural";
    case SceneKind::kHighway:
      return "highway";
    case SceneKind::kPlaza:
      return "plaza";
    case SceneKind::kIntersection:
      return "intersection";
  }
  return "unknown";
}

StatusOr<SceneKind> ParseSceneKind(const std::string& name) {
  for (int k = 0; k < kNumSceneKinds; ++k) {
    if (name == SceneKindName(static_cast<SceneKind>(k))) return static_cast<SceneKind>(k);
  }
  return InvalidArgumentError("unknown scene kind '" + name +
                              "' (urban, avenue, rural, highway, plaza or intersection)");
}

SceneOptions SceneOptionsFor(SceneKind kind) {
  SceneOptions o;
  o.kind = kind;
  switch (kind) {
    case SceneKind::kUrban:
      break;
    case SceneKind::kAvenue:  // wide, facades far behind two rows of dense trees
      o.road_half_width_min_m = 6.0;
      o.road_half_width_max_m = 8.0;
      o.facade_offset_min_m = 14.0;
      o.facade_offset_max_m = 20.0;
      o.gap_probability = 0.1;
      o.tree_spacing_min_m = 6.0;
      o.tree_spacing_max_m = 9.0;
      o.tree_probability = 0.95;
      o.bend_radius_min_m = 40.0;
      o.bend_radius_max_m = 80.0;
      break;
    case SceneKind::kRural:  // no buildings: fields to 50 m, scattered trees, rails
      o.road_half_width_min_m = 3.0;
      o.road_half_width_max_m = 3.6;
      o.facade_offset_min_m = o.facade_offset_max_m = 50.0;  // the field's extent
      o.setback_min_m = o.setback_max_m = 0.0;
      o.bend_angle_min_deg = 10.0;
      o.bend_angle_max_deg = 35.0;
      o.bend_radius_min_m = 120.0;
      o.bend_radius_max_m = 300.0;
      o.straight_min_m = 20.0;
      o.straight_max_m = 70.0;
      o.tree_spacing_min_m = 5.0;
      o.tree_spacing_max_m = 25.0;
      o.tree_probability = 0.7;
      o.tree_lateral_min_m = 2.5;
      o.tree_lateral_max_m = 30.0;
      break;
    case SceneKind::kHighway:  // two carriageways, rails, fields, far trees, wide bends
      o.road_half_width_min_m = 8.7;
      o.road_half_width_max_m = 12.3;
      o.facade_offset_min_m = o.facade_offset_max_m = 60.0;
      o.setback_min_m = o.setback_max_m = 0.0;
      o.bend_angle_min_deg = 3.0;
      o.bend_angle_max_deg = 12.0;
      o.bend_radius_min_m = 400.0;
      o.bend_radius_max_m = 1200.0;
      o.straight_min_m = 60.0;
      o.straight_max_m = 200.0;
      o.tree_spacing_min_m = 8.0;
      o.tree_spacing_max_m = 40.0;
      o.tree_probability = 0.6;
      o.tree_lateral_min_m = 8.0;
      o.tree_lateral_max_m = 40.0;
      break;
    case SceneKind::kPlaza:  // an open lot: stalls, cars, lamp posts, far buildings
      o.road_half_width_min_m = 24.0;
      o.road_half_width_max_m = 28.0;
      o.facade_offset_min_m = 32.0;
      o.facade_offset_max_m = 45.0;
      o.gap_probability = 0.0;
      o.bend_angle_min_deg = 15.0;
      o.bend_angle_max_deg = 45.0;
      o.bend_radius_min_m = 60.0;
      o.bend_radius_max_m = 90.0;
      o.straight_min_m = 30.0;
      o.straight_max_m = 60.0;
      o.trees = false;
      break;
    case SceneKind::kIntersection:  // city blocks joined by 90-degree corners
      o.straight_min_m = 14.0;
      o.straight_max_m = 30.0;
      o.bend_angle_min_deg = o.bend_angle_max_deg = 90.0;
      o.bend_radius_min_m = 20.0;
      o.bend_radius_max_m = 26.0;
      o.facade_offset_min_m = 7.0;
      o.facade_offset_max_m = 9.0;
      o.gap_probability = 0.3;
      o.tree_probability = 0.4;
      break;
  }
  return o;
}

namespace {

// Radians per degree (angles.h: DegToRad(1) is exactly pi / 180). The path
// and scene multiply by it, which is not DegToRad's x * pi / 180 bit for bit:
// kept so that simulated drives stay identical.
const double kDeg = DegToRad(1.0);
using Eigen::Vector2d;
using Eigen::Vector3d;
using Polygon = std::vector<Vector3d>;

Vector3d To3(const Vector2d& p, double z = 0.0) { return {p.x(), p.y(), z}; }

// One slot along a side of the street: a building or a side-street gap.
struct Lot {
  bool gap = false;
  double s0_m = 0, s1_m = 0;
  double offset_m = 0;  // |lateral offset| of the facade line
  double height_m = 0;
};

// Largest distance between the offset curve and its chord over [s0, s1].
double ChordDeviation(const Centreline& cl, double s0, double s1, double lateral) {
  const Vector2d a = cl.Offset(s0, lateral), b = cl.Offset(s1, lateral);
  const Vector2d dir = (b - a).normalized();
  const Vector2d n(-dir.y(), dir.x());
  double dev = 0.0;
  for (int k = 1; k < 8; ++k) {
    dev = std::max(dev, std::abs((cl.Offset(s0 + (s1 - s0) * k / 8.0, lateral) - a).dot(n)));
  }
  return dev;
}

double SegmentDistance(const Vector2d& p, const Vector2d& a, const Vector2d& b) {
  const Vector2d d = b - a;
  const double t = std::clamp((p - a).dot(d) / std::max(d.squaredNorm(), 1e-12), 0.0, 1.0);
  return (p - a - t * d).norm();
}

// Distance from p to a convex polygon (0 inside).
double PolygonDistance(const Vector2d& p, const std::vector<Vector2d>& poly) {
  bool inside = true;
  double best = 1e300;
  double sign = 0.0;
  for (size_t k = 0; k < poly.size(); ++k) {
    const Vector2d& a = poly[k];
    const Vector2d& b = poly[(k + 1) % poly.size()];
    const double cross = (b - a).x() * (p - a).y() - (b - a).y() * (p - a).x();
    if (sign == 0.0) sign = cross >= 0 ? 1.0 : -1.0;
    if (cross * sign < 0) inside = false;
    best = std::min(best, SegmentDistance(p, a, b));
  }
  return inside ? 0.0 : best;
}

cv::Vec3f Jitter(SimRandom& rng, const cv::Vec3f& c, float amount) {
  return {static_cast<float>(c[0] + rng.Uniform(-amount, amount)),
          static_cast<float>(c[1] + rng.Uniform(-amount, amount)),
          static_cast<float>(c[2] + rng.Uniform(-amount, amount))};
}

FacadeStyle MakeFacadeStyle(SimRandom& rng, double width, double height, bool allow_shop) {
  static const cv::Vec3f kPlaster[] = {
      {170, 205, 225}, {140, 200, 225}, {150, 170, 215}, {185, 188, 190}, {165, 200, 180},
      {205, 190, 175}, {90, 160, 205},  {210, 215, 218}, {175, 170, 220}, {120, 140, 160}};
  static const cv::Vec3f kBrick[] = {
      {55, 75, 150}, {45, 55, 120}, {60, 85, 125}, {110, 165, 195}, {70, 90, 160}};
  static const cv::Vec3f kSign[] = {{40, 40, 200},  {170, 80, 30},  {60, 140, 40},
                                    {40, 200, 230}, {30, 30, 30},   {235, 235, 235},
                                    {30, 130, 235}, {130, 50, 110}, {150, 140, 20}};
  FacadeStyle f;
  f.width_m = width;
  f.height_m = height;
  f.brick = rng.Bernoulli(0.4);
  if (f.brick) {
    f.wall_bgr = Jitter(rng, kBrick[rng.UniformInt(0, 4)], 10);
    const float m = static_cast<float>(rng.Uniform(160, 190));
    f.mortar_bgr = {m, m + 3, m + 5};
  } else {
    f.wall_bgr = Jitter(rng, kPlaster[rng.UniformInt(0, 9)], 10);
  }
  if (rng.Bernoulli(0.7)) {
    const float t = static_cast<float>(rng.Uniform(212, 238));
    f.trim_bgr = {t, t, t - 4};
  } else {
    const float t = static_cast<float>(rng.Uniform(50, 80));
    f.trim_bgr = {t, t + 4, t + 8};
  }
  f.ground_floor_m = rng.Uniform(3.6, 4.6);
  f.floor_m = rng.Uniform(2.8, 3.4);
  f.window_w_m = rng.Uniform(1.0, 1.4);
  f.window_h_m = std::min(rng.Uniform(1.3, 1.8), f.floor_m - 1.2);
  f.window_pitch_m = rng.Uniform(std::max(2.5, f.window_w_m + 0.9), 3.5);
  const int cols = std::max(
      1, static_cast<int>(std::floor((width - 0.6 - f.window_w_m) / f.window_pitch_m)) + 1);
  f.window_u0_m = 0.5 * (width - (cols - 1) * f.window_pitch_m);
  f.sill_m = rng.Uniform(0.8, 1.0);
  f.mullions = rng.Bernoulli(0.6);
  f.cornices = rng.Bernoulli(0.5);
  f.shop = rng.Bernoulli(0.5) && allow_shop && width > 5.0;
  f.sign_u0_m = rng.Uniform(0.3, 0.8);
  f.sign_u1_m = width - rng.Uniform(0.3, 0.8);
  f.sign_bgr = kSign[rng.UniformInt(0, 8)];
  const float lum = 0.114f * f.sign_bgr[0] + 0.587f * f.sign_bgr[1] + 0.299f * f.sign_bgr[2];
  const bool alt = rng.Bernoulli(0.3);
  if (lum > 140) {
    f.glyph_bgr = alt ? cv::Vec3f(30, 30, 190) : cv::Vec3f(25, 25, 25);
  } else {
    f.glyph_bgr = alt ? cv::Vec3f(40, 220, 245) : cv::Vec3f(245, 245, 245);
  }
  f.door_w_m = rng.Uniform(1.0, 1.4);
  const double door_room = width - f.door_w_m - 0.8;
  f.door_u_m = door_room > 0 ? 0.4 + rng.Uniform(0.0, door_room) : 0.5 * (width - f.door_w_m);
  return f;
}

class StreetBuilder {
 public:
  StreetBuilder(const SceneOptions& o, Scene* scene)
      : o_(o), scene_(scene), rng_(Mix64(o.seed ^ 0x5354524545540001ULL)) {}

  Status Build();

 private:
  void BuildCentreline();
  void BuildSide(int side);
  void BuildMarkings();
  void BuildTrees();
  void AddTree(double s, double lateral, double size = 1.0);
  // The other kinds' parts (none of them draws from rng_ for kUrban).
  void SetUpCrossSection();
  void VaryAppearance();
  void BuildGuardRails();
  void AddGuardRail(double s0, double s1, double lateral, const Vector2d& towards_side);
  void BuildParking();
  // A box (footprint centred at xy, `length` along `yaw`, `width` across),
  // z0..z1: its four sides and top as planes of `kind`, or as clutter when
  // `planes` is false; each face gets its own texture (a copy of `tex`).
  void AddBox(const Vector2d& xy, double yaw, double length, double width, double z0, double z1,
              const TextureDesc& tex, bool planes, PlaneKind kind);
  void AddClutterSurface(int texture, const Vector3d& origin, const Vector3d& u, const Vector3d& v,
                         const Polygon& poly);
  bool BuiltUp() const { return o_.kind != SceneKind::kRural && o_.kind != SceneKind::kHighway; }
  void AddRoadPlane();
  // A vertical rectangle a-b (world xy), height h, facing the point `towards`.
  int AddWall(PlaneKind kind, const Vector2d& a, const Vector2d& b, double h,
              const Vector2d& towards, int texture, double z0 = 0.0);
  int AddFacade(const Vector2d& a, const Vector2d& b, double h, const Vector2d& towards,
                bool allow_shop);
  // Distant blocks on the vertical line through `centre` with horizontal
  // direction `along`, facing `towards`; width in metres.
  int AddBackground(const Vector2d& centre, const Vector2d& along, double width,
                    const Vector2d& towards, bool windows = true);
  float Gain(const Vector3d& n) const {
    return static_cast<float>(0.8 + 0.28 * std::max(0.0, n.head<2>().dot(sun_)));
  }
  // True if nothing of the street's ground strip comes within `clearance` of the
  // polygon, ignoring centreline stations within `skip_m` of s_skip.
  bool ClearOfRoad(const std::vector<Vector2d>& poly, double s_skip, double skip_m) const;

  const SceneOptions& o_;
  Scene* scene_;
  SimRandom rng_;
  double s_begin_ = -10.0, s_end_ = 0.0;
  double base_offset_[2] = {0, 0};  // facade line |offset| per side: 0 right, 1 left
  Vector2d sun_ = Vector2d::UnitX();
  std::vector<Polygon> road_polygons_;
  std::vector<int> leaf_textures_;
  int bark_texture_ = -1;
  int lanes_ = 1;  // kHighway: lanes per carriageway
};

Status StreetBuilder::Build() {
  Scene& sc = *scene_;
  sc.seed = o_.seed;
  s_end_ = o_.length_m + 60.0;  // the usable street plus a closing stretch
  BuildCentreline();
  RoadStyle& road = sc.road;
  sc.kind = o_.kind;
  road.half_width_m = rng_.Uniform(o_.road_half_width_min_m, o_.road_half_width_max_m);
  sc.lane_offset_m = -0.5 * road.half_width_m;
  if (o_.kind != SceneKind::kUrban) SetUpCrossSection();
  road.s_begin_m = s_begin_;
  road.s_end_m = s_end_;
  for (int side = 0; side < 2; ++side) {
    const double lo =
        std::max(o_.facade_offset_min_m, road.half_width_m + road.curb_m + 1.3 + o_.setback_max_m);
    base_offset_[side] = rng_.Uniform(lo, std::max(lo, o_.facade_offset_max_m));
  }
  road.strip_right_m = base_offset_[0] + o_.setback_max_m + 1.0;
  road.strip_left_m = base_offset_[1] + o_.setback_max_m + 1.0;
  const double sun_az = rng_.Uniform(0.0, 2.0 * M_PI);
  sun_ = Vector2d(std::cos(sun_az), std::sin(sun_az));
  if (o_.appearance_variety) VaryAppearance();

  // Plane 0 is the road; its polygons are complete only after the side streets.
  TextureDesc road_tex;
  road_tex.kind = TextureKind::kRoad;
  road_tex.seed = HashCombine(o_.seed, 0x40AD);
  road_tex.texel_m = o_.road_texel_m;
  const int tex = sc.AddTexture(road_tex);
  sc.AddPlane(PlaneKind::kRoad, Vector3d::UnitZ(), {}, Vector3d::Zero(), Vector3d::UnitX(),
              -Vector3d::UnitY(), tex);

  // Ground strip: quads between stations (arcs every <= 3 degrees).
  const Centreline& cl = sc.centreline;
  std::vector<double> stations = {s_begin_};
  while (stations.back() < s_end_) {
    const double s = stations.back();
    const double k = std::abs(cl.Curvature(s + 1e-6));
    double next = std::min(s + (k > 0 ? 3.0 * kDeg / k : 40.0), s_end_);
    for (const auto& seg : cl.segments()) {
      if (seg.s0_m > s + 1e-6 && seg.s0_m < next) next = seg.s0_m;
    }
    stations.push_back(next);
  }
  for (size_t k = 0; k + 1 < stations.size(); ++k) {
    const double a = stations[k], b = stations[k + 1];
    road_polygons_.push_back(
        {To3(cl.Offset(a, -road.strip_right_m)), To3(cl.Offset(b, -road.strip_right_m)),
         To3(cl.Offset(b, road.strip_left_m)), To3(cl.Offset(a, road.strip_left_m))});
  }

  if (BuiltUp()) {
    BuildSide(0);
    BuildSide(1);
  }
  // Close the street with distant blocks (a tree line without buildings) across its end.
  const Vector2d end = cl.Point(s_end_), t_end = cl.Tangent(s_end_);
  AddBackground(end, Vector2d(-t_end.y(), t_end.x()), road.strip_left_m + road.strip_right_m + 80.0,
                end - t_end, BuiltUp());
  BuildMarkings();
  if (o_.trees) BuildTrees();
  if (o_.kind == SceneKind::kRural || o_.kind == SceneKind::kHighway) BuildGuardRails();
  if (o_.kind == SceneKind::kPlaza) BuildParking();
  AddRoadPlane();
  return Status::Ok();
}

void StreetBuilder::BuildCentreline() {
  Centreline cl;
  double heading = 0.0;
  cl.AddStraight(rng_.Uniform(o_.straight_min_m, o_.straight_max_m));
  while (cl.length_m() < s_end_ + 10.0) {
    const double angle = rng_.Uniform(o_.bend_angle_min_deg, o_.bend_angle_max_deg) * kDeg;
    const double radius = rng_.Uniform(o_.bend_radius_min_m, o_.bend_radius_max_m);
    double sign = rng_.Sign();
    // Keep the street's general direction so it never loops back on itself.
    if (std::abs(heading) > 30.0 * kDeg) sign = heading > 0 ? -1.0 : 1.0;
    cl.AddArc(angle * radius, sign / radius);
    heading += sign * angle;
    cl.AddStraight(rng_.Uniform(o_.straight_min_m, o_.straight_max_m));
  }
  scene_->centreline = cl;
}

int StreetBuilder::AddWall(PlaneKind kind, const Vector2d& a, const Vector2d& b, double h,
                           const Vector2d& towards, int texture, double z0) {
  const Vector2d d = (b - a).normalized();
  Vector3d n(-d.y(), d.x(), 0.0);
  if (n.head<2>().dot(towards - a) < 0) n = -n;
  // Seen from the front: u runs right, v down.
  const Vector3d u_axis = (-n).cross(Vector3d::UnitZ());
  const Vector3d v_axis = -Vector3d::UnitZ();
  const Vector3d A = To3(a, z0), B = To3(b, z0);
  const Vector3d left = u_axis.dot(A) <= u_axis.dot(B) ? A : B;
  // h is the top's height above the ground (the wall spans z0..h).
  const Vector3d up = (h - z0) * Vector3d::UnitZ();
  const Polygon poly = {A, B, B + up, A + up};
  scene_->textures[texture].gain = Gain(n);
  return scene_->AddPlane(kind, n, {poly}, left + up, u_axis, v_axis, texture);
}

int StreetBuilder::AddFacade(const Vector2d& a, const Vector2d& b, double h,
                             const Vector2d& towards, bool allow_shop) {
  Scene& sc = *scene_;
  sc.facades.push_back(MakeFacadeStyle(rng_, (b - a).norm(), h, allow_shop));
  TextureDesc tex;
  tex.kind = TextureKind::kFacade;
  tex.seed = HashCombine(o_.seed, 0xFACADE00ULL + sc.planes.size());
  tex.style = static_cast<int>(sc.facades.size()) - 1;
  tex.texel_m = o_.facade_texel_m;
  return AddWall(PlaneKind::kFacade, a, b, h, towards, sc.AddTexture(tex));
}

int StreetBuilder::AddBackground(const Vector2d& centre, const Vector2d& along, double width,
                                 const Vector2d& towards, bool windows) {
  Scene& sc = *scene_;
  BackgroundStyle style;
  style.windows = windows;
  for (double u = 0.0; u < width - 1e-6;) {
    const double w = std::min(rng_.Uniform(10.0, 30.0), width - u);
    BackgroundStyle::Block blk;
    blk.u0_m = u;
    blk.u1_m = u + w;
    blk.height_m = rng_.Uniform(18.0, 60.0);
    const float g = static_cast<float>(rng_.Uniform(110, 190));
    blk.bgr = Jitter(rng_, cv::Vec3f(g + 8, g, g - 6), 12);
    if (!windows) {  // a tree line or hills: lower, green-grey
      blk.height_m *= 0.3;
      blk.bgr = Jitter(rng_, cv::Vec3f(0.55f * g, 0.75f * g, 0.6f * g), 10);
    }
    style.blocks.push_back(blk);
    style.top_m = std::max(style.top_m, blk.height_m);
    u += w;
  }
  sc.backgrounds.push_back(style);
  TextureDesc tex;
  tex.kind = TextureKind::kBackground;
  tex.seed = HashCombine(o_.seed, 0xBA0000ULL + sc.planes.size());
  tex.style = static_cast<int>(sc.backgrounds.size()) - 1;
  tex.texel_m = o_.background_texel_m;
  const int texture = sc.AddTexture(tex);

  const Vector2d dir = along.normalized();
  Vector3d n(-dir.y(), dir.x(), 0.0);
  if (n.head<2>().dot(towards - centre) < 0) n = -n;
  const Vector3d u_axis = (-n).cross(Vector3d::UnitZ());
  const Vector3d left = To3(centre) - 0.5 * width * u_axis;
  std::vector<Polygon> polys;
  for (const auto& blk : style.blocks) {
    const Vector3d a = left + blk.u0_m * u_axis, b = left + blk.u1_m * u_axis;
    const Vector3d up = blk.height_m * Vector3d::UnitZ();
    polys.push_back({a, b, b + up, a + up});
  }
  sc.textures[texture].gain = 0.92f;
  return sc.AddPlane(PlaneKind::kBackground, n, polys, left + style.top_m * Vector3d::UnitZ(),
                     u_axis, -Vector3d::UnitZ(), texture);
}

bool StreetBuilder::ClearOfRoad(const std::vector<Vector2d>& poly, double s_skip,
                                double skip_m) const {
  const Centreline& cl = scene_->centreline;
  const double clearance = std::max(scene_->road.strip_left_m, scene_->road.strip_right_m) + 3.0;
  for (double s = s_begin_ - 60.0; s <= s_end_ + 60.0; s += 2.0) {
    if (std::abs(s - s_skip) < skip_m) continue;
    if (PolygonDistance(cl.Point(s), poly) < clearance) return false;
  }
  return true;
}

void StreetBuilder::BuildSide(int side) {
  const Centreline& cl = scene_->centreline;
  const double sigma = side == 0 ? -1.0 : 1.0;  // lateral sign: right < 0, left > 0
  // Lots: buildings and side-street gaps along the side.
  std::vector<Lot> lots;
  bool prev_gap = true;
  for (double s = s_begin_; s < s_end_ - 1.0;) {
    Lot lot;
    lot.s0_m = s;
    lot.height_m = rng_.Uniform(o_.building_height_min_m, o_.building_height_max_m);
    lot.offset_m =
        base_offset_[side] + rng_.Sign() * rng_.Uniform(o_.setback_min_m, o_.setback_max_m);
    const bool gap_ok = !prev_gap && s > s_begin_ + 20.0 && s < s_end_ - 40.0;
    if (rng_.Bernoulli(o_.gap_probability) && gap_ok) {
      lot.gap = true;
      lot.s1_m = s + rng_.Uniform(o_.gap_width_min_m, o_.gap_width_max_m);
    } else {
      double w = rng_.Uniform(o_.building_width_min_m, o_.building_width_max_m);
      // Chords must stay close to the curved facade line in bends.
      while (w > 4.0 && ChordDeviation(cl, s, s + w, sigma * lot.offset_m) > 0.8) w *= 0.8;
      if (s_end_ - (s + w) < 4.0) w = s_end_ - s;
      lot.s1_m = s + w;
    }
    prev_gap = lot.gap;
    s = lot.s1_m;
    lots.push_back(lot);
  }

  // Side streets: a canyon floor (part of the road plane), the far wall (the
  // next building's side) and distant blocks closing the canyon.
  for (size_t i = 1; i + 1 < lots.size(); ++i) {
    Lot& gap = lots[i];
    if (!gap.gap) continue;
    const Lot& a = lots[i - 1];
    const Lot& b = lots[i + 1];
    const double s_mid = 0.5 * (gap.s0_m + gap.s1_m);
    const Vector2d pa = cl.Offset(gap.s0_m, sigma * a.offset_m);
    const Vector2d pb = cl.Offset(gap.s1_m, sigma * b.offset_m);
    const Vector2d out = sigma * cl.Left(s_mid);
    const Vector2d along(out.y(), -out.x());
    const double width = (pb - pa).norm();
    double depth = rng_.Uniform(o_.background_distance_min_m, o_.background_distance_max_m);
    bool ok = false;
    for (; depth >= 0.5 * o_.background_distance_min_m; depth *= 0.8) {
      const Vector2d q = 0.5 * (pa + pb) + depth * out;
      const std::vector<Vector2d> canyon = {pa, pb, pb + depth * out, pa + depth * out};
      const double bw = width + 0.6 * depth;
      const std::vector<Vector2d> bg = {q - 0.5 * bw * along, q + 0.5 * bw * along,
                                        q + 0.5 * bw * along + 0.1 * out,
                                        q - 0.5 * bw * along + 0.1 * out};
      if (ClearOfRoad(canyon, s_mid, 30.0) && ClearOfRoad(bg, s_mid, 0.0)) {
        ok = true;
        break;
      }
    }
    if (!ok) {
      gap.gap = false;  // no room for a side street: a building stands there
      continue;
    }
    road_polygons_.push_back({To3(pa), To3(pb), To3(pb + depth * out), To3(pa + depth * out)});
    AddFacade(pb, pb + depth * out, b.height_m, pa, /*allow_shop=*/false);
    AddBackground(0.5 * (pa + pb) + depth * out, along, width + 0.6 * depth, 0.5 * (pa + pb));
  }

  // Facades, and the side walls of buildings that stand out towards the
  // oncoming camera (closer to the road or taller than their predecessor).
  for (size_t i = 0; i < lots.size(); ++i) {
    const Lot& lot = lots[i];
    if (lot.gap) continue;
    const Vector2d a = cl.Offset(lot.s0_m, sigma * lot.offset_m);
    const Vector2d b = cl.Offset(lot.s1_m, sigma * lot.offset_m);
    AddFacade(a, b, lot.height_m, cl.Point(0.5 * (lot.s0_m + lot.s1_m)), /*allow_shop=*/true);
    if (i == 0 || lots[i - 1].gap) continue;
    const Lot& prev = lots[i - 1];
    if (lot.offset_m < prev.offset_m - 0.05 || lot.height_m > prev.height_m + 0.3) {
      const Vector2d back = cl.Offset(lot.s0_m, sigma * (lot.offset_m + 8.0));
      AddFacade(a, back, lot.height_m, a - cl.Tangent(lot.s0_m), /*allow_shop=*/false);
    }
  }
}

void StreetBuilder::BuildMarkings() {
  RoadStyle& road = scene_->road;
  const Centreline& cl = scene_->centreline;
  const double hw = road.half_width_m;
  if (o_.kind == SceneKind::kRural || o_.kind == SceneKind::kHighway) return;  // lines only
  if (o_.kind == SceneKind::kPlaza) {
    for (double s = rng_.Uniform(10.0, 30.0); s < s_end_; s += rng_.Uniform(30.0, 60.0)) {
      road.arrows.push_back({s, scene_->lane_offset_m, true});
    }
    return;
  }
  for (double s = rng_.Uniform(50.0, 120.0); s < s_end_ - 20.0; s += rng_.Uniform(120.0, 220.0)) {
    road.crosswalk_s_m.push_back(s);
    road.arrows.push_back({s - 15.0, -0.5 * hw, true});
    road.arrows.push_back({s + 19.0, 0.5 * hw, false});
  }
  for (double s = rng_.Uniform(20.0, 60.0); s < s_end_; s += rng_.Uniform(50.0, 110.0)) {
    road.arrows.push_back({s, -0.5 * hw, true});
  }
  for (double s = s_begin_ + rng_.Uniform(5.0, 40.0); s < s_end_; s += rng_.Uniform(20.0, 60.0)) {
    const double lateral = rng_.Sign() * (0.5 * hw + rng_.Uniform(-0.6, 0.6));
    road.manholes.push_back({cl.Offset(s, lateral), 0.3});
  }
}

void StreetBuilder::BuildTrees() {
  Scene& sc = *scene_;
  const double hw = sc.road.half_width_m;
  leaf_textures_.clear();
  static const float kLeafGain[] = {0.5f, 0.62f, 0.75f, 0.88f, 1.0f, 1.12f};
  for (int k = 0; k < 6; ++k) {
    TextureDesc tex;
    tex.kind = TextureKind::kLeaves;
    tex.seed = HashCombine(o_.seed, 0x1EAF00ULL + k);
    tex.gain = kLeafGain[k];
    tex.texel_m = 0.01;
    tex.tile_texels = 80;
    leaf_textures_.push_back(sc.AddTexture(tex));
  }
  TextureDesc bark;
  bark.kind = TextureKind::kBark;
  bark.seed = HashCombine(o_.seed, 0xBA4CULL);
  bark.texel_m = 0.01;
  bark_texture_ = sc.AddTexture(bark);
  for (int side = 0; side < 2; ++side) {
    const double sigma = side == 0 ? -1.0 : 1.0;
    for (double s = s_begin_ + rng_.Uniform(0.0, o_.tree_spacing_max_m); s < s_end_ - 5.0;
         s += rng_.Uniform(o_.tree_spacing_min_m, o_.tree_spacing_max_m)) {
      const double lateral = sigma * (hw + sc.road.curb_m + sc.road.shoulder_m +
                                      rng_.Uniform(o_.tree_lateral_min_m, o_.tree_lateral_max_m));
      if (o_.kind == SceneKind::kUrban) {
        if (rng_.Bernoulli(o_.tree_probability)) AddTree(s, lateral);
        continue;
      }
      if (!rng_.Bernoulli(o_.tree_probability)) continue;
      AddTree(s, lateral, rng_.Uniform(0.7, 1.4));
      // The avenue's second row, in front of the facades.
      if (o_.kind == SceneKind::kAvenue)
        AddTree(s + rng_.Uniform(-2.0, 2.0), lateral + sigma * 4.0);
    }
  }
}

void StreetBuilder::AddTree(double s, double lateral, double size) {
  Scene& sc = *scene_;
  const Vector3d base = To3(sc.centreline.Offset(s, lateral));
  const double zc = size * rng_.Uniform(4.0, 5.0);
  // Keep the canopy clear of the camera in the right lane.
  const double r_max =
      std::max(1.0, std::min(2.2 * size, std::abs(lateral - sc.lane_offset_m) - 1.2));
  const double rxy = rng_.Uniform(std::min(1.4, r_max), r_max);
  const double rz = size * rng_.Uniform(1.2, 1.5);
  auto add_surface = [&](int texture, const Vector3d& origin, const Vector3d& u, const Vector3d& v,
                         const Polygon& poly) { AddClutterSurface(texture, origin, u, v, poly); };
  // Trunk: a square prism up to the canopy centre.
  const double a = rng_.Uniform(0.12, 0.17), yaw = rng_.Uniform(0.0, 0.5 * M_PI);
  const Vector3d e1(std::cos(yaw), std::sin(yaw), 0.0), e2(-std::sin(yaw), std::cos(yaw), 0.0);
  const Vector3d corners[4] = {base + a * (e1 + e2), base + a * (-e1 + e2), base + a * (-e1 - e2),
                               base + a * (e1 - e2)};
  const Vector3d up = zc * Vector3d::UnitZ();
  for (int k = 0; k < 4; ++k) {
    const Vector3d& p = corners[k];
    const Vector3d& q = corners[(k + 1) % 4];
    const Vector3d n = ((p + q) * 0.5 - base).normalized();
    const Vector3d u = (-n).cross(Vector3d::UnitZ());
    const Vector3d left = u.dot(p) <= u.dot(q) ? p : q;
    add_surface(bark_texture_, left + up + 0.37 * k * u, u, -Vector3d::UnitZ(),
                {p, q, q + up, p + up});
  }
  // Canopy: small randomly oriented hexagonal leaf clusters in an ellipsoid.
  for (int k = 0; k < o_.leaves_per_tree; ++k) {
    Vector3d p;
    do {
      p = Vector3d(rng_.Uniform(-1, 1), rng_.Uniform(-1, 1), rng_.Uniform(-1, 1));
    } while (p.squaredNorm() > 1.0);
    const Vector3d centre = base + Vector3d(rxy * p.x(), rxy * p.y(), zc + rz * p.z());
    const double r = rng_.Uniform(0.18, 0.32);
    Vector3d n(rng_.Normal(), rng_.Normal(), rng_.Normal());
    n.normalize();
    const Vector3d ref = std::abs(n.z()) < 0.9 ? Vector3d::UnitZ() : Vector3d::UnitX();
    const Vector3d u = n.cross(ref).normalized();
    const Vector3d v = u.cross(n);
    const double phase = rng_.Uniform(0.0, M_PI / 3.0);
    Polygon hex;
    for (int m = 0; m < 6; ++m) {
      const double th = phase + m * M_PI / 3.0;
      hex.push_back(centre + r * (std::cos(th) * u + std::sin(th) * v));
    }
    const int variant = std::clamp(static_cast<int>(p.norm() * 4.0 + rng_.Uniform(0.0, 2.0)), 0, 5);
    // The leaf texture tile is 0.8 m square; the cluster sits at its centre.
    add_surface(leaf_textures_[variant], centre - 0.4 * u - 0.4 * v, u, v, hex);
  }
}

void StreetBuilder::AddClutterSurface(int texture, const Vector3d& origin, const Vector3d& u,
                                      const Vector3d& v, const Polygon& poly) {
  Surface surf;
  surf.label = kMbClutter;
  surf.texture = texture;
  surf.origin_world = origin;
  surf.u_axis_world = u;
  surf.v_axis_world = v;
  surf.polygons_world = {poly};
  scene_->surfaces.push_back(surf);
}

// The cross-section of the kinds other than kUrban (after the half width was drawn).
void StreetBuilder::SetUpCrossSection() {
  Scene& sc = *scene_;
  RoadStyle& road = sc.road;
  if (BuiltUp()) return;  // curbs and sidewalks as in the city
  road.curb_m = 0.0;
  road.verge = RoadStyle::Verge::kField;
  road.shoulder_m = rng_.Uniform(0.4, 1.5);
  road.field_row_m = rng_.Uniform(0.5, 1.2);
  if (o_.kind == SceneKind::kRural) {
    road.dash_period_m = rng_.Uniform(9.0, 15.0);
    road.dash_length_m = rng_.Uniform(2.5, 4.5);
    sc.lane_offset_m = -0.5 * road.half_width_m;
    return;
  }
  // Highway: a 0.8 m median, lanes of 3.6 m, a hard shoulder up to the edge.
  lanes_ = rng_.Bernoulli(0.5) ? 2 : 3;
  const double median_m = 0.8, lane_m = 3.6;
  road.half_width_m = median_m + lanes_ * lane_m + rng_.Uniform(0.8, 2.5);
  road.dash_period_m = 18.0;
  road.dash_length_m = 6.0;
  road.dash_lateral_m.clear();
  road.solid_lateral_m = {-median_m, median_m, -(median_m + lanes_ * lane_m),
                          median_m + lanes_ * lane_m};
  for (int k = 1; k < lanes_; ++k) {
    road.dash_lateral_m.push_back(-(median_m + k * lane_m));
    road.dash_lateral_m.push_back(median_m + k * lane_m);
  }
  sc.lane_offset_m = -(median_m + (rng_.UniformInt(0, lanes_ - 1) + 0.5) * lane_m);
}

// Road appearance, markings, light and sky from a random stream of their own.
void StreetBuilder::VaryAppearance() {
  Scene& sc = *scene_;
  RoadStyle& road = sc.road;
  SimRandom look(Mix64(o_.seed ^ 0x100C0FFEEULL));
  Lighting& light = sc.lighting;
  light.exposure = static_cast<float>(look.Uniform(0.7, 1.25));
  for (int c = 0; c < 3; ++c) light.tint[c] = static_cast<float>(look.Uniform(0.94, 1.06));
  if (look.Bernoulli(0.35)) {  // overcast
    const int g = look.UniformInt(170, 225);
    light.sky_horizon_bgr = cv::Vec3b(g, g, g);
    light.sky_zenith_bgr = cv::Vec3b(g - 25, g - 22, g - 20);
  } else {
    light.sky_horizon_bgr =
        cv::Vec3b(look.UniformInt(215, 245), look.UniformInt(205, 230), look.UniformInt(190, 220));
    light.sky_zenith_bgr =
        cv::Vec3b(look.UniformInt(180, 225), look.UniformInt(120, 170), look.UniformInt(70, 120));
  }
  const float a = static_cast<float>(look.Uniform(55, 115));
  road.asphalt_bgr = cv::Vec3f(a, a + static_cast<float>(look.Uniform(-3, 4)),
                               a + static_cast<float>(look.Uniform(-2, 8)));
  road.grain = static_cast<float>(look.Uniform(0.5, 1.6));
  road.paint_wear = static_cast<float>(look.Uniform(0.0, 0.6));
  road.paint_bgr = look.Bernoulli(0.2) ? cv::Vec3f(70, 200, 230) : cv::Vec3f(222, 228, 232);
  if (o_.kind != SceneKind::kHighway) {
    road.dash_period_m *= look.Uniform(0.7, 1.3);
    road.dash_length_m =
        std::min(road.dash_length_m * look.Uniform(0.7, 1.3), 0.8 * road.dash_period_m);
  }
  static const cv::Vec3f kFields[] = {{60, 120, 95},   // grass
                                      {70, 150, 175},  // stubble
                                      {60, 85, 110},   // ploughed soil
                                      {50, 105, 80}};  // meadow
  road.field_bgr = kFields[look.UniformInt(0, 3)];
}

void StreetBuilder::BuildGuardRails() {
  const RoadStyle& road = scene_->road;
  const Centreline& cl = scene_->centreline;
  const double edge = road.half_width_m + road.shoulder_m + 0.3;
  for (int side = 0; side < 2; ++side) {
    const double sigma = side == 0 ? -1.0 : 1.0;
    if (o_.kind == SceneKind::kHighway) {  // continuous along both edges
      AddGuardRail(s_begin_, s_end_, sigma * edge, Vector2d::Zero());
      continue;
    }
    // Rural: stretches of rail (bends, embankments) with gaps between them.
    for (double s = s_begin_ + rng_.Uniform(0.0, 40.0); s < s_end_ - 10.0;) {
      const double len = rng_.Uniform(40.0, 160.0);
      if (rng_.Bernoulli(0.6)) AddGuardRail(s, std::min(s + len, s_end_), sigma * edge, {});
      s += len + rng_.Uniform(10.0, 80.0);
    }
  }
  // The highway's median rail, facing the carriageway the camera drives on.
  if (o_.kind == SceneKind::kHighway) AddGuardRail(s_begin_, s_end_, -0.45, {});
  (void)cl;
}

// Rail pieces (chords of the offset curve within 2 cm of it), beam face from
// 0.45 to 0.75 m, facing the centreline; posts every 2-4 m behind the beam.
void StreetBuilder::AddGuardRail(double s0, double s1, double lateral, const Vector2d&) {
  Scene& sc = *scene_;
  const Centreline& cl = sc.centreline;
  const double out = lateral > 0 ? 1.0 : -1.0;
  const double face = lateral;  // the beam's face
  TextureDesc metal;
  metal.kind = TextureKind::kMetal;
  metal.texel_m = 0.01;
  metal.tile_texels = 128;
  const float g = static_cast<float>(rng_.Uniform(140, 185));
  metal.base_bgr = cv::Vec3f(g + 4, g + 2, g);
  for (double s = s0; s < s1 - 0.5;) {
    double len = std::min(12.0, s1 - s);
    while (len > 1.0 && ChordDeviation(cl, s, s + len, face) > 0.02) len *= 0.7;
    const Vector2d a = cl.Offset(s, face), b = cl.Offset(s + len, face);
    const Vector2d towards = cl.Offset(s + 0.5 * len, face - out * 5.0);
    metal.seed = HashCombine(o_.seed, 0x4A11ULL + sc.textures.size());
    AddWall(PlaneKind::kGuardRail, a, b, 0.75, towards, sc.AddTexture(metal), 0.45);
    s += len;
  }
  TextureDesc post;
  post.kind = TextureKind::kPaint;
  post.texel_m = 0.01;
  post.tile_texels = 64;
  post.base_bgr = metal.base_bgr * 0.6f;
  const double spacing = rng_.Uniform(2.0, 4.0);
  for (double s = s0 + 0.5 * spacing; s < s1; s += spacing) {
    post.seed = HashCombine(o_.seed, 0x9057ULL + static_cast<uint64_t>(s * 100));
    AddBox(cl.Offset(s, face + out * 0.12), cl.Heading(s), 0.12, 0.12, 0.0, 0.72, post,
           /*planes=*/false, PlaneKind::kObject);
  }
}

// The lot: stalls both sides of the aisle, parked cars (boxes whose faces are
// planes of kind kObject), lamp posts (clutter).
void StreetBuilder::BuildParking() {
  Scene& sc = *scene_;
  RoadStyle& road = sc.road;
  const Centreline& cl = sc.centreline;
  sc.lane_offset_m = -2.0;
  road.dash_lateral_m.clear();
  road.stall_lateral_min_m = 5.0;
  road.stall_lateral_max_m = 10.0;
  road.stall_period_m = rng_.Uniform(2.4, 2.8);
  static const cv::Vec3f kCar[] = {{40, 40, 40},   {200, 200, 200}, {60, 60, 160},
                                   {140, 80, 40},  {150, 150, 150}, {30, 90, 30},
                                   {40, 140, 200}, {235, 235, 235}};
  TextureDesc paint;
  paint.kind = TextureKind::kPaint;
  paint.texel_m = 0.02;
  paint.tile_texels = 128;
  paint.style = 1;  // car: a dark window band near the top of the sides
  for (int side = 0; side < 2; ++side) {
    const double sigma = side == 0 ? -1.0 : 1.0;
    for (double s = s_begin_ + 10.0 + 0.5 * road.stall_period_m; s < s_end_ - 10.0;
         s += road.stall_period_m) {
      if (!rng_.Bernoulli(0.55)) continue;
      const double lateral = sigma * rng_.Uniform(7.2, 7.8);
      paint.seed = HashCombine(o_.seed, 0xCA40ULL + sc.textures.size());
      paint.base_bgr = Jitter(rng_, kCar[rng_.UniformInt(0, 7)], 8);
      AddBox(cl.Offset(s, lateral), cl.Heading(s) + M_PI / 2 + rng_.Uniform(-0.05, 0.05),
             rng_.Uniform(4.1, 4.8), rng_.Uniform(1.7, 1.9), 0.0, rng_.Uniform(1.35, 1.6), paint,
             /*planes=*/true, PlaneKind::kObject);
    }
  }
  TextureDesc pole;
  pole.kind = TextureKind::kPaint;
  pole.texel_m = 0.01;
  pole.tile_texels = 64;
  pole.base_bgr = cv::Vec3f(110, 115, 120);
  for (double s = s_begin_ + rng_.Uniform(5.0, 20.0); s < s_end_; s += rng_.Uniform(18.0, 30.0)) {
    for (double sigma : {-1.0, 1.0}) {
      pole.seed = HashCombine(o_.seed, 0x90E0ULL + sc.textures.size());
      AddBox(cl.Offset(s, sigma * 12.0), cl.Heading(s), 0.18, 0.18, 0.0, 6.0, pole,
             /*planes=*/false, PlaneKind::kObject);
    }
  }
}

void StreetBuilder::AddBox(const Vector2d& xy, double yaw, double length, double width, double z0,
                           double z1, const TextureDesc& tex, bool planes, PlaneKind kind) {
  Scene& sc = *scene_;
  const Vector2d e1(std::cos(yaw), std::sin(yaw)), e2(-std::sin(yaw), std::cos(yaw));
  const double hl = 0.5 * length, hw = 0.5 * width;
  const Vector2d c[4] = {xy + hl * e1 + hw * e2, xy - hl * e1 + hw * e2, xy - hl * e1 - hw * e2,
                         xy + hl * e1 - hw * e2};
  for (int k = 0; k < 4; ++k) {  // sides, facing out
    const Vector2d& a = c[k];
    const Vector2d& b = c[(k + 1) % 4];
    const Vector2d mid = 0.5 * (a + b);
    const int t = sc.AddTexture(tex);
    if (planes) {
      AddWall(kind, a, b, z1, mid + (mid - xy), t, z0);
      continue;
    }
    Vector3d n = To3(mid - xy).normalized();
    sc.textures[t].gain = Gain(n);
    const Vector3d u = (-n).cross(Vector3d::UnitZ());
    const Vector3d A = To3(a, z0), B = To3(b, z0), up(0, 0, z1 - z0);
    const Vector3d left = u.dot(A) <= u.dot(B) ? A : B;
    AddClutterSurface(t, left + up, u, -Vector3d::UnitZ(), {A, B, B + up, A + up});
  }
  // Top: u along e1, v along -e2 (u x v = -z: seen from above).
  const Polygon top = {To3(c[0], z1), To3(c[1], z1), To3(c[2], z1), To3(c[3], z1)};
  const int t = sc.AddTexture(tex);
  sc.textures[t].gain = 1.1f;
  const Vector3d origin = To3(c[1], z1), u = To3(e1), v = -To3(e2);
  if (planes) {
    sc.AddPlane(kind, Vector3d::UnitZ(), {top}, origin, u, v, t);
  } else {
    AddClutterSurface(t, origin, u, v, top);
  }
}

void StreetBuilder::AddRoadPlane() {
  Scene& sc = *scene_;
  double xmin = 1e300, ymax = -1e300;
  for (const auto& poly : road_polygons_) {
    for (const auto& p : poly) {
      xmin = std::min(xmin, p.x());
      ymax = std::max(ymax, p.y());
    }
  }
  // Texture frame: u along +x, v along -y, from the strip's bounding box corner.
  const Vector3d origin(std::floor(xmin) - 1.0, std::ceil(ymax) + 1.0, 0.0);
  sc.planes[0].polygons_world = road_polygons_;
  sc.planes[0].distance_m = 0.0;
  Surface& surf = sc.surfaces[0];
  surf.origin_world = origin;
  surf.u_axis_world = Vector3d::UnitX();
  surf.v_axis_world = -Vector3d::UnitY();
  surf.polygons_world = road_polygons_;
  sc.road.origin_xy = origin.head<2>();
  sc.road.u_xy = Vector2d::UnitX();
  sc.road.v_xy = -Vector2d::UnitY();
}

Status ValidateOptions(const SceneOptions& o) {
  auto range = [](double lo, double hi) { return lo > 0 && hi >= lo && std::isfinite(hi); };
  if (!(o.length_m > 0 && o.length_m <= 20000)) {
    return InvalidArgumentError("scene length_m must be in (0, 20000], got " +
                                std::to_string(o.length_m));
  }
  if (!range(o.straight_min_m, o.straight_max_m) ||
      !range(o.bend_angle_min_deg, o.bend_angle_max_deg) || o.bend_angle_max_deg > 90 ||
      !range(o.bend_radius_min_m, o.bend_radius_max_m)) {
    return InvalidArgumentError("bad centreline ranges (straights, bend angles, radii)");
  }
  if (!range(o.road_half_width_min_m, o.road_half_width_max_m) ||
      !range(o.facade_offset_min_m, o.facade_offset_max_m) ||
      !(o.setback_min_m >= 0 && o.setback_max_m >= o.setback_min_m)) {
    return InvalidArgumentError("bad cross-section ranges (road width, facade offsets, setback)");
  }
  const double strip =
      std::max(o.facade_offset_max_m, o.road_half_width_max_m + 1.5 + o.setback_max_m) +
      o.setback_max_m + 1.0;
  if (o.bend_radius_min_m < strip + 5.0) {
    return InvalidArgumentError("bend_radius_min_m must exceed the street's half-width + 5 m");
  }
  if (!range(o.building_width_min_m, o.building_width_max_m) ||
      !range(o.building_height_min_m, o.building_height_max_m) ||
      !range(o.gap_width_min_m, o.gap_width_max_m) ||
      !range(o.background_distance_min_m, o.background_distance_max_m) ||
      !(o.gap_probability >= 0 && o.gap_probability <= 1)) {
    return InvalidArgumentError("bad building / side street ranges");
  }
  if (o.trees && (!range(o.tree_spacing_min_m, o.tree_spacing_max_m) || o.leaves_per_tree < 0 ||
                  o.leaves_per_tree > 10000)) {
    return InvalidArgumentError("bad tree options");
  }
  if (!(o.road_texel_m >= 0.002 && o.facade_texel_m >= 0.002 && o.background_texel_m >= 0.002)) {
    return InvalidArgumentError("texel sizes must be >= 2 mm");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<Scene> GenerateStreetScene(const SceneOptions& options) {
  SLAPSE_RETURN_IF_ERROR(ValidateOptions(options));
  Scene scene;
  StreetBuilder builder(options, &scene);
  SLAPSE_RETURN_IF_ERROR(builder.Build());
  return scene;
}

}  // namespace slapse
