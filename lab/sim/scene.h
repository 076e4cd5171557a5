// The simulated street scene: planes (the ground truth), the textured surfaces
// the renderer draws, and the parameters of their procedural textures.
//
// Conventions: world frame z up, road plane z = 0, metres. A surface carries a
// texture frame: the point with texture coordinates (u, v) (metres) is
//   origin_world + u * u_axis_world + v * v_axis_world,
// with u_axis x v_axis = -(normal towards the viewer), i.e. u runs right and
// v runs down as seen from the front, like image columns and rows. The
// level-0 texel (a, b) covers u in [a, a+1) * texel_m, v in [b, b+1) * texel_m.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/centreline.h"

namespace slapse {

// kMetal: a guard rail's beam (bands along u, bolts, rust); kPaint: a plain
// painted surface of colour `base_bgr` with grain (car bodies, posts).
enum class TextureKind { kRoad, kFacade, kBackground, kLeaves, kBark, kChecker, kMetal, kPaint };

// What a simulated drive passes through (lab/sim/scene.cc, docs/TRAJECTORY.md):
//   kUrban        the street canyon: facades 7-11 m from the centreline, trees at the curbs
//   kAvenue       wide street, facades 14-20 m away behind two rows of dense trees
//   kRural        two-lane road without buildings: fields, scattered trees, guard rails
//   kHighway      two carriageways of 2-3 lanes, guard rails, fields, far trees, wide bends
//   kPlaza        open parking lot: parking stalls, parked cars (boxes), lamp posts,
//                 buildings 30-45 m away
//   kIntersection city streets joined by 90-degree turns at street corners
enum class SceneKind { kUrban, kAvenue, kRural, kHighway, kPlaza, kIntersection };
constexpr int kNumSceneKinds = 6;
// "urban", "avenue", "rural", "highway", "plaza", "intersection".
const char* SceneKindName(SceneKind kind);
StatusOr<SceneKind> ParseSceneKind(const std::string& name);

struct TextureDesc {
  TextureKind kind = TextureKind::kChecker;
  uint64_t seed = 0;
  // Index into Scene::facades (kFacade) or Scene::backgrounds (kBackground).
  int style = -1;
  // Brightness factor baked into the texture (shading by the surface's orientation).
  float gain = 1.0f;
  // Level-0 texel size in metres and tile size in texels: textures are made and
  // cached tile by tile, tile (i, j) covering texels [i, i+1) * tile_texels (u) x
  // [j, j+1) * tile_texels (v).
  double texel_m = 0.02;
  int tile_texels = 160;
  // kChecker only: squares of checker_m metres, the square at the origin dark.
  double checker_m = 0.5;
  cv::Vec3b checker_dark{20, 20, 20};
  cv::Vec3b checker_light{235, 235, 235};
  // kPaint and kMetal: the base colour.
  cv::Vec3f base_bgr{160, 160, 160};
};

struct Surface {
  // Plane id (>= 0, index into Scene::planes) or kMbClutter for non-planar clutter.
  int label = kMbClutter;
  int texture = -1;  // index into Scene::textures
  Eigen::Vector3d origin_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d u_axis_world = Eigen::Vector3d::UnitX();  // unit
  Eigen::Vector3d v_axis_world = Eigen::Vector3d::UnitY();  // unit, orthogonal to u
  // Convex polygons (world) lying on the surface; what is drawn.
  std::vector<std::vector<Eigen::Vector3d>> polygons_world;
};

// Parameters of one facade texture (texture coordinates: u from the wall's left
// edge as seen from the front, v down from the wall's top, metres).
struct FacadeStyle {
  double width_m = 10.0;
  double height_m = 12.0;
  bool brick = false;
  cv::Vec3f wall_bgr{150, 170, 190};
  cv::Vec3f trim_bgr{220, 220, 220};  // window frames, cornices
  cv::Vec3f mortar_bgr{170, 175, 180};
  double ground_floor_m = 4.0;  // height of the ground floor
  double floor_m = 3.0;         // height of upper floors
  double window_w_m = 1.2, window_h_m = 1.6;
  double window_pitch_m = 3.0;  // centre-to-centre, horizontal
  double window_u0_m = 1.5;     // centre of the first window column
  double sill_m = 0.9;          // window bottom above its floor
  bool mullions = true;
  bool cornices = true;
  bool shop = false;  // ground floor shop: sign board and display windows
  double sign_u0_m = 0.5, sign_u1_m = 9.5;
  cv::Vec3f sign_bgr{40, 40, 200};
  cv::Vec3f glyph_bgr{250, 250, 250};
  double door_u_m = 4.0, door_w_m = 1.2;  // door: left edge and width
};

// A wall of distant city blocks (kind kBackground); u, v as for facades, v
// measured down from top_m above the ground.
struct BackgroundStyle {
  struct Block {
    double u0_m, u1_m, height_m;
    cv::Vec3f bgr;
  };
  double top_m = 60.0;
  std::vector<Block> blocks;
  // False: a tree line or hills (no window grid, more texture noise).
  bool windows = true;
};

struct RoadStyle {
  double half_width_m = 5.0;  // asphalt, centreline to curb
  double curb_m = 0.18;       // curb stone width beyond the asphalt
  // The street's ground strip (asphalt, curbs, sidewalks) reaches these lateral
  // distances left and right of the centreline (beyond the facades).
  double strip_left_m = 12.0, strip_right_m = 12.0;
  double s_begin_m = 0.0, s_end_m = 0.0;  // street extent along the centreline
  double dash_period_m = 9.0, dash_length_m = 3.0;
  std::vector<double> crosswalk_s_m;  // start of each crosswalk (stripes 4 m long)
  struct Arrow {
    double s_m, lateral_m;
    bool forward;  // points towards +s
  };
  std::vector<Arrow> arrows;
  struct Manhole {
    Eigen::Vector2d xy;
    double radius_m;
  };
  std::vector<Manhole> manholes;
  // Road texture frame (copied from the road surface): world xy of (u, v).
  Eigen::Vector2d origin_xy = Eigen::Vector2d::Zero();
  Eigen::Vector2d u_xy = Eigen::Vector2d::UnitX(), v_xy = -Eigen::Vector2d::UnitY();
  // Appearance (the defaults are the urban street's). Beyond the curb: paved
  // sidewalk (kSidewalk) or, without a curb, a gravel shoulder of shoulder_m
  // and then grass / ploughed field (kField).
  enum class Verge { kSidewalk, kField };
  Verge verge = Verge::kSidewalk;
  double shoulder_m = 0.0;
  cv::Vec3f asphalt_bgr{84, 86, 88};
  cv::Vec3f paint_bgr{222, 228, 232};
  cv::Vec3f field_bgr{60, 120, 95};  // kField: the field's mean colour
  double field_row_m = 0.8;          // kField: furrow spacing
  float grain = 1.0f;                // scale of the asphalt's noise
  float paint_wear = 0.0f;           // 0: fresh markings, 1: mostly worn off
  // Dashed lines at these lateral offsets (the centre line by default) and
  // solid lines; the edge lines at |l| = half_width - 0.3..0.45 are always drawn.
  std::vector<double> dash_lateral_m = {0.0};
  std::vector<double> solid_lateral_m;
  // Parking stalls: lines across the lot every stall_period_m where
  // stall_lateral_min_m <= |l| <= stall_lateral_max_m (none when max <= min).
  double stall_lateral_min_m = 0.0, stall_lateral_max_m = 0.0, stall_period_m = 2.6;
};

// The light of a scene: a global exposure and colour tint applied to every
// texture, and the sky (lab/sim/renderer.h RenderOptions' defaults).
struct Lighting {
  float exposure = 1.0f;
  cv::Vec3f tint{1.0f, 1.0f, 1.0f};
  cv::Vec3b sky_horizon_bgr{232, 222, 212};
  cv::Vec3b sky_zenith_bgr{205, 150, 100};
};

struct Scene {
  uint64_t seed = 0;
  SceneKind kind = SceneKind::kUrban;
  Lighting lighting;
  Centreline centreline;
  RoadStyle road;
  double lane_offset_m = -2.5;  // lateral offset of the right lane's centre (< 0: right)
  std::vector<GtPlane> planes;  // planes[i].id == i; plane 0 is the road in street scenes
  std::vector<Surface> surfaces;
  std::vector<TextureDesc> textures;
  std::vector<FacadeStyle> facades;
  std::vector<BackgroundStyle> backgrounds;

  // Adds a plane with one surface covering its polygons and returns its id.
  // `normal_world` must be unit and point to the side the camera sees.
  int AddPlane(PlaneKind kind, const Eigen::Vector3d& normal_world,
               const std::vector<std::vector<Eigen::Vector3d>>& polygons_world,
               const Eigen::Vector3d& origin_world, const Eigen::Vector3d& u_axis_world,
               const Eigen::Vector3d& v_axis_world, int texture);
  int AddTexture(const TextureDesc& desc);
};

struct SceneOptions {
  uint64_t seed = 1;
  // The layout; the ranges below are the urban street's. SceneOptionsFor(kind)
  // gives each kind's ranges.
  SceneKind kind = SceneKind::kUrban;
  // Vary road appearance, markings, lighting and sky with the seed (drawn
  // from a stream of their own: the geometry of a seed does not change).
  bool appearance_variety = false;
  // Centreline: straights and circular bends, starting and ending with a straight.
  double length_m = 500.0;  // at least this much street
  double straight_min_m = 30.0, straight_max_m = 80.0;
  double bend_angle_min_deg = 10.0, bend_angle_max_deg = 40.0;
  double bend_radius_min_m = 25.0, bend_radius_max_m = 60.0;
  // Cross-section.
  double road_half_width_min_m = 4.0, road_half_width_max_m = 6.0;
  double facade_offset_min_m = 7.0, facade_offset_max_m = 11.0;  // from the centreline
  double setback_min_m = 0.3, setback_max_m = 1.5;               // per-building jitter magnitude
  // Buildings.
  double building_width_min_m = 8.0, building_width_max_m = 25.0;
  double building_height_min_m = 8.0, building_height_max_m = 25.0;
  double gap_probability = 0.15;  // side street instead of the next building
  double gap_width_min_m = 8.0, gap_width_max_m = 15.0;
  double background_distance_min_m = 80.0, background_distance_max_m = 200.0;
  // Trees on the sidewalks (non-planar clutter).
  bool trees = true;
  double tree_spacing_min_m = 9.0, tree_spacing_max_m = 18.0;
  double tree_probability = 0.6;  // per slot
  int leaves_per_tree = 160;
  // Where trees stand: beyond the curb by this much (|lateral| - half width - curb).
  double tree_lateral_min_m = 0.6, tree_lateral_max_m = 1.0;
  // Texture resolution (metres per level-0 texel).
  double road_texel_m = 0.02, facade_texel_m = 0.025, background_texel_m = 0.1;
};

// Each kind's ranges (seed 1, appearance_variety off); kUrban: SceneOptions{}.
SceneOptions SceneOptionsFor(SceneKind kind);

// Generates a scene of options.kind deterministically from options.seed.
StatusOr<Scene> GenerateStreetScene(const SceneOptions& options);

}  // namespace slapse
