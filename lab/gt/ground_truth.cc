// Reading and writing the ground truth of a simulated drive (formats in ground_truth.h).
//
// JSON goes through nlohmann::json (core/common/json_io.h), numbers with 17
// significant digits so doubles round-trip exactly. Text files are parsed
// line by line; lines starting with '#' are comments.
#include "lab/gt/ground_truth.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/common/json_io.h"
#include "core/common/mb_grid.h"

namespace slapse {

const char* PlaneKindName(PlaneKind kind) {
  switch (kind) {
    case PlaneKind::kRoad:
      return "road";
    case PlaneKind::kFacade:
      return "facade";
    case PlaneKind::kBackground:
      return "background";
    case PlaneKind::kGuardRail:
      return "guard_rail";
    case PlaneKind::kObject:
      return "object";
  }
  return "unknown";
}

bool GroundTruth::TransferThroughPlane(int plane_id, int frame, int other,
                                       const Eigen::Vector2d& x_px,
                                       Eigen::Vector2d* x_other_px) const {
  const int n = static_cast<int>(frames.size());
  if (plane_id < 0 || plane_id >= static_cast<int>(planes.size()) || frame < 0 || frame >= n ||
      other < 0 || other >= n) {
    return false;
  }
  const GtPlane& p = planes[plane_id];
  const Rigid3d& world_from_cam = frames[frame].world_from_cam;
  const Eigen::Vector3d ray = world_from_cam.rotation * intrinsics.Unproject(x_px);
  const double denom = p.normal_world.dot(ray);
  if (std::abs(denom) < 1e-12) return false;
  // Ray parameter s with z = 1 rays: s is the depth in the camera of `frame`.
  const double s = (p.distance_m - p.normal_world.dot(world_from_cam.translation)) / denom;
  if (s < 0.1) return false;
  const Eigen::Vector3d x_other =
      frames[other].world_from_cam.Inverse() * (world_from_cam.translation + s * ray);
  if (x_other.z() < 0.1) return false;
  *x_other_px = intrinsics.Project(x_other);
  return true;
}

int GroundTruth::LabelAt(int frame, double x_px, double y_px) const {
  if (frame < 0 || frame >= static_cast<int>(frames.size())) return kMbMixed;
  // Pixel centres are at integers, so macroblock column c covers x in [16c - 0.5, 16c + 15.5).
  if (!(std::abs(x_px) < 1e9 && std::abs(y_px) < 1e9)) return kMbMixed;  // also NaN
  const int fc = MbCellOf(x_px), fr = MbCellOf(y_px);
  if (!(fc >= 0 && fc < mb_cols && fr >= 0 && fr < mb_rows)) return kMbMixed;
  const std::vector<int>& labels = frames[frame].mb_labels;
  if (labels.size() != static_cast<size_t>(mb_cols) * mb_rows) return kMbMixed;
  return labels[static_cast<size_t>(fr) * mb_cols + static_cast<size_t>(fc)];
}

namespace {

std::string Num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

Status WriteFile(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return UnavailableError("cannot open " + path.string() + " for writing");
  out << text;
  out.close();
  if (!out) return DataLossError("failed writing " + path.string());
  return Status::Ok();
}

bool Finite(const Eigen::Vector3d& v) { return v.allFinite(); }

Status CheckFinite(const GroundTruth& gt) {
  const Intrinsics& k = gt.intrinsics;
  if (!std::isfinite(k.fx_px) || !std::isfinite(k.fy_px) || !std::isfinite(k.cx_px) ||
      !std::isfinite(k.cy_px) || !std::isfinite(gt.fps)) {
    return InvalidArgumentError("ground truth has non-finite intrinsics or fps");
  }
  for (const GtPlane& p : gt.planes) {
    if (!Finite(p.normal_world) || !std::isfinite(p.distance_m)) {
      return InvalidArgumentError("plane " + std::to_string(p.id) + " is not finite");
    }
    for (const auto& poly : p.polygons_world) {
      for (const auto& v : poly) {
        if (!Finite(v)) return InvalidArgumentError("plane polygon vertex is not finite");
      }
    }
  }
  for (const GtFrame& f : gt.frames) {
    if (!std::isfinite(f.timestamp_s) || !Finite(f.world_from_cam.translation) ||
        !f.world_from_cam.rotation.coeffs().allFinite()) {
      return InvalidArgumentError("frame pose is not finite");
    }
  }
  return Status::Ok();
}

Json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

Status ReadVec3(const Json& obj, const std::string& key, const std::string& where,
                Eigen::Vector3d* out) {
  return GetNumbers(obj, key, where, 3, out->data());
}

StatusOr<PlaneKind> ParsePlaneKind(const std::string& kind, const std::string& where) {
  if (kind == "road") return PlaneKind::kRoad;
  if (kind == "facade") return PlaneKind::kFacade;
  if (kind == "background") return PlaneKind::kBackground;
  if (kind == "guard_rail") return PlaneKind::kGuardRail;
  if (kind == "object") return PlaneKind::kObject;
  return DataLossError(where + ": unknown kind '" + kind + "'");
}

// One element of planes.json's "planes".
StatusOr<GtPlane> ReadPlane(const Json& node, const std::string& where) {
  GtPlane p;
  SLAPSE_RETURN_IF_ERROR(GetInt(node, "id", where, &p.id));
  std::string kind;
  SLAPSE_RETURN_IF_ERROR(GetString(node, "kind", where, &kind));
  auto parsed = ParsePlaneKind(kind, where);
  if (!parsed.ok()) return parsed.status();
  p.kind = *parsed;
  SLAPSE_RETURN_IF_ERROR(ReadVec3(node, "normal_world", where, &p.normal_world));
  SLAPSE_RETURN_IF_ERROR(GetNumber(node, "distance_m", where, &p.distance_m));
  const auto polys = node.find("polygons");
  if (polys == node.end()) return p;
  if (!polys->is_array()) return DataLossError(where + ": key 'polygons' is not a list");
  for (size_t i = 0; i < polys->size(); ++i) {
    const Json& poly = (*polys)[i];
    const std::string at = where + ": polygons[" + std::to_string(i) + "]";
    if (!poly.is_array()) return DataLossError(at + " is not a list");
    std::vector<Eigen::Vector3d> vs;
    for (const Json& v : poly) {
      bool ok = v.is_array() && v.size() == 3;
      for (size_t k = 0; ok && k < 3; ++k) ok = v[k].is_number();
      if (!ok) return DataLossError(at + ": a vertex is not a list of 3 numbers");
      vs.emplace_back(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
    }
    p.polygons_world.push_back(std::move(vs));
  }
  return p;
}

Status LoadIntrinsics(const std::filesystem::path& path, Intrinsics* k) {
  auto doc = ReadJsonFile(path.string());
  if (!doc.ok()) return doc.status();
  const std::string where = path.string();
  SLAPSE_RETURN_IF_ERROR(GetNumber(*doc, "fx_px", where, &k->fx_px));
  SLAPSE_RETURN_IF_ERROR(GetNumber(*doc, "fy_px", where, &k->fy_px));
  SLAPSE_RETURN_IF_ERROR(GetNumber(*doc, "cx_px", where, &k->cx_px));
  SLAPSE_RETURN_IF_ERROR(GetNumber(*doc, "cy_px", where, &k->cy_px));
  SLAPSE_RETURN_IF_ERROR(GetInt(*doc, "width_px", where, &k->width_px));
  return GetInt(*doc, "height_px", where, &k->height_px);
}

Status LoadPlanes(const std::filesystem::path& path, std::vector<GtPlane>* planes) {
  auto doc = ReadJsonFile(path.string());
  if (!doc.ok()) return doc.status();
  const auto list = doc->find("planes");
  if (list == doc->end()) return Status::Ok();
  if (!list->is_array()) return DataLossError(path.string() + ": key 'planes' is not a list");
  for (size_t i = 0; i < list->size(); ++i) {
    auto p = ReadPlane((*list)[i], path.string() + ": planes[" + std::to_string(i) + "]");
    if (!p.ok()) return p.status();
    if (p->id != static_cast<int>(planes->size())) {
      return DataLossError(path.string() + ": plane ids must be 0, 1, 2, ... in order");
    }
    planes->push_back(std::move(*p));
  }
  return Status::Ok();
}

// trajectory_tum.txt: one GtFrame per pose line.
Status LoadTrajectory(const std::filesystem::path& root, GroundTruth* out) {
  GroundTruth& gt = *out;
  const auto path = root / "trajectory_tum.txt";
  std::ifstream in(path);
  if (!in) return NotFoundError("missing " + path.string());
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    GtFrame f;
    double tx, ty, tz, qx, qy, qz, qw;
    if (!(ls >> f.timestamp_s >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) {
      return DataLossError(path.string() + ":" + std::to_string(line_no) + ": bad pose line");
    }
    f.world_from_cam = Rigid3d(Eigen::Quaterniond(qw, qx, qy, qz), Eigen::Vector3d(tx, ty, tz));
    gt.frames.push_back(f);
  }
  return Status::Ok();
}

// mb_labels.txt: each frame's macroblock labels (and the grid size).
Status LoadMbLabels(const std::filesystem::path& root, GroundTruth* out) {
  GroundTruth& gt = *out;
  const auto path = root / "mb_labels.txt";
  std::ifstream in(path);
  if (!in) return NotFoundError("missing " + path.string());
  std::string line;
  size_t frame = 0;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    long index;
    int cols, rows;
    const std::string where = path.string() + ":" + std::to_string(line_no);
    if (!(ls >> index >> cols >> rows) || cols <= 0 || rows <= 0 || cols > 4096 || rows > 4096) {
      return DataLossError(where + ": bad header");
    }
    if (index != static_cast<long>(frame) || frame >= gt.frames.size()) {
      return DataLossError(where + ": frame index does not match the trajectory");
    }
    if (frame == 0) {
      gt.mb_cols = cols;
      gt.mb_rows = rows;
    } else if (cols != gt.mb_cols || rows != gt.mb_rows) {
      return DataLossError(where + ": macroblock grid changed");
    }
    std::vector<int>& labels = gt.frames[frame].mb_labels;
    labels.resize(static_cast<size_t>(cols) * rows);
    for (int& l : labels) {
      if (!(ls >> l)) return DataLossError(where + ": too few labels");
    }
    ++frame;
  }
  if (frame != gt.frames.size()) {
    return DataLossError(path.string() + ": " + std::to_string(frame) + " label lines for " +
                         std::to_string(gt.frames.size()) + " poses");
  }
  return Status::Ok();
}

// mb_mixed.txt: the shares of the mixed blocks. Optional: drives simulated
// before it existed have no shares.
Status LoadMixedShares(const std::filesystem::path& root, GroundTruth* out) {
  GroundTruth& gt = *out;
  const auto path = root / "mb_mixed.txt";
  if (!std::filesystem::exists(path)) return Status::Ok();
  std::ifstream in(path);
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    const std::string where = path.string() + ":" + std::to_string(line_no);
    std::istringstream ls(line);
    long frame;
    int mb_index;
    if (!(ls >> frame >> mb_index) || frame < 0 || frame >= static_cast<long>(gt.frames.size()) ||
        mb_index < 0 || mb_index >= gt.mb_cols * gt.mb_rows) {
      return DataLossError(where + ": bad frame or macroblock index");
    }
    std::vector<MbShare>& shares = gt.frames[frame].mixed_shares[mb_index];
    std::string item;
    while (ls >> item) {
      MbShare share;
      char colon = 0;
      std::istringstream is(item);
      if (!(is >> share.label >> colon >> share.share) || colon != ':' ||
          !(share.share > 0.0f && share.share <= 1.0f)) {
        return DataLossError(where + ": bad label:share '" + item + "'");
      }
      shares.push_back(share);
    }
    if (shares.empty()) return DataLossError(where + ": no shares");
  }
  return Status::Ok();
}

// trajectory_tum.txt
std::string TrajectoryText(const GroundTruth& gt) {
  std::ostringstream traj;
  traj << "# timestamp_s tx ty tz qx qy qz qw  (world_from_cam; world z up, road plane z = 0)\n";
  for (const GtFrame& f : gt.frames) {
    const Eigen::Vector3d& t = f.world_from_cam.translation;
    const Eigen::Quaterniond& q = f.world_from_cam.rotation;
    traj << Num(f.timestamp_s) << ' ' << Num(t.x()) << ' ' << Num(t.y()) << ' ' << Num(t.z()) << ' '
         << Num(q.x()) << ' ' << Num(q.y()) << ' ' << Num(q.z()) << ' ' << Num(q.w()) << '\n';
  }
  return traj.str();
}

// intrinsics.json
std::string IntrinsicsJsonText(const Intrinsics& k) {
  Json intr;
  intr["fx_px"] = k.fx_px;
  intr["fy_px"] = k.fy_px;
  intr["cx_px"] = k.cx_px;
  intr["cy_px"] = k.cy_px;
  intr["width_px"] = k.width_px;
  intr["height_px"] = k.height_px;
  return DumpJson(intr, ExactNumber);
}

// planes.json
std::string PlanesJsonText(const std::vector<GtPlane>& gt_planes) {
  Json planes;
  Json& list = planes["planes"] = Json::array();
  for (const GtPlane& p : gt_planes) {
    Json plane;
    plane["id"] = p.id;
    plane["kind"] = PlaneKindName(p.kind);
    plane["normal_world"] = Vec(p.normal_world);
    plane["distance_m"] = p.distance_m;
    Json& polygons = plane["polygons"] = Json::array();
    for (const auto& poly : p.polygons_world) {
      Json vertices = Json::array();
      for (const Eigen::Vector3d& v : poly) vertices.push_back(Vec(v));
      polygons.push_back(std::move(vertices));
    }
    list.push_back(std::move(plane));
  }
  return DumpJson(planes, ExactNumber);
}

// mb_labels.txt
std::string MbLabelsText(const GroundTruth& gt) {
  std::ostringstream mb;
  mb << "# frame_index mb_cols mb_rows labels... (row-major; plane id >= 0, " << kMbSky << " sky, "
     << kMbClutter << " clutter, " << kMbMixed << " mixed)\n";
  for (size_t i = 0; i < gt.frames.size(); ++i) {
    mb << i << ' ' << gt.mb_cols << ' ' << gt.mb_rows;
    for (int l : gt.frames[i].mb_labels) mb << ' ' << l;
    mb << '\n';
  }
  return mb.str();
}

// mb_mixed.txt
std::string MbMixedText(const GroundTruth& gt) {
  std::ostringstream mixed;
  mixed << "# frame_index mb_index label:share... (the blocks labelled " << kMbMixed
        << " in mb_labels.txt: what their pixels see, largest share first)\n";
  for (size_t i = 0; i < gt.frames.size(); ++i) {
    for (const auto& [mb_index, shares] : gt.frames[i].mixed_shares) {
      mixed << i << ' ' << mb_index;
      for (const MbShare& s : shares) mixed << ' ' << s.label << ':' << s.share;
      mixed << '\n';
    }
  }
  return mixed.str();
}

}  // namespace

Status SaveGroundTruth(const GroundTruth& gt, const std::string& dir) {
  SLAPSE_RETURN_IF_ERROR(CheckFinite(gt));
  for (size_t i = 0; i < gt.planes.size(); ++i) {
    if (gt.planes[i].id != static_cast<int>(i)) {
      return InvalidArgumentError("planes must be indexed by id (planes[i].id == i)");
    }
  }
  for (const GtFrame& f : gt.frames) {
    if (f.mb_labels.size() != static_cast<size_t>(gt.mb_cols) * gt.mb_rows) {
      return InvalidArgumentError("frame label count does not match mb_cols * mb_rows");
    }
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return UnavailableError("cannot create " + dir + ": " + ec.message());
  const std::filesystem::path root(dir);

  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "trajectory_tum.txt", TrajectoryText(gt)));
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "intrinsics.json", IntrinsicsJsonText(gt.intrinsics)));
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "planes.json", PlanesJsonText(gt.planes)));
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "mb_labels.txt", MbLabelsText(gt)));
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "mb_mixed.txt", MbMixedText(gt)));

  // Minimal meta.json; SimulateDrive replaces it with a superset.
  Json meta;
  meta["fps"] = gt.fps;
  meta["frames"] = gt.frames.size();
  meta["mb_cols"] = gt.mb_cols;
  meta["mb_rows"] = gt.mb_rows;
  return WriteFile(root / "meta.json", DumpJson(meta, ExactNumber));
}

StatusOr<GroundTruth> LoadGroundTruth(const std::string& dir) {
  const std::filesystem::path root(dir);
  GroundTruth gt;

  SLAPSE_RETURN_IF_ERROR(LoadIntrinsics(root / "intrinsics.json", &gt.intrinsics));
  SLAPSE_RETURN_IF_ERROR(LoadPlanes(root / "planes.json", &gt.planes));

  SLAPSE_RETURN_IF_ERROR(LoadTrajectory(root, &gt));
  SLAPSE_RETURN_IF_ERROR(LoadMbLabels(root, &gt));
  SLAPSE_RETURN_IF_ERROR(LoadMixedShares(root, &gt));

  // fps from meta.json, else from the timestamps.
  Status meta = Status::Ok();
  if (auto doc = ReadJsonFile((root / "meta.json").string()); doc.ok()) {
    meta = GetNumber(*doc, "fps", (root / "meta.json").string(), &gt.fps);
  } else {
    meta = doc.status();
  }
  if (!meta.ok() && meta.code() != StatusCode::kNotFound) return meta;
  if (!meta.ok() && gt.frames.size() >= 2) {
    const double span = gt.frames.back().timestamp_s - gt.frames.front().timestamp_s;
    if (span > 0) gt.fps = (gt.frames.size() - 1) / span;
  }
  return gt;
}

}  // namespace slapse
