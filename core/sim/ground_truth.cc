// Reading and writing the ground truth of a simulated drive (formats in ground_truth.h).
//
// JSON is written by hand (numbers with 17 significant digits, so doubles
// round-trip exactly) and read back with cv::FileStorage. Text files are
// parsed line by line; lines starting with '#' are comments.
#include "core/sim/ground_truth.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/core.hpp>

namespace slapse {

const char* PlaneKindName(PlaneKind kind) {
  switch (kind) {
    case PlaneKind::kRoad:
      return "road";
    case PlaneKind::kFacade:
      return "facade";
    case PlaneKind::kBackground:
      return "background";
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
  const double fc = std::floor((x_px + 0.5) / 16.0), fr = std::floor((y_px + 0.5) / 16.0);
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

std::string Vec(const Eigen::Vector3d& v) {
  return "[" + Num(v.x()) + ", " + Num(v.y()) + ", " + Num(v.z()) + "]";
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

// Runs `fn` (which reads with cv::FileStorage) and turns OpenCV exceptions into a Status.
template <typename Fn>
Status ReadJson(const std::filesystem::path& path, Fn fn) {
  if (!std::filesystem::exists(path)) return NotFoundError("missing " + path.string());
  try {
    cv::FileStorage fs(path.string(), cv::FileStorage::READ | cv::FileStorage::FORMAT_JSON);
    if (!fs.isOpened()) return DataLossError("cannot parse " + path.string());
    return fn(fs);
  } catch (const cv::Exception& e) {
    return DataLossError("cannot parse " + path.string() + ": " + e.what());
  }
}

Status ReadNumber(const cv::FileNode& node, const std::string& what, double* out) {
  if (node.empty() || (!node.isReal() && !node.isInt())) {
    return DataLossError("missing or non-numeric '" + what + "'");
  }
  *out = static_cast<double>(node);
  return Status::Ok();
}

Status ReadVec3(const cv::FileNode& node, const std::string& what, Eigen::Vector3d* out) {
  if (!node.isSeq() || node.size() != 3) return DataLossError("'" + what + "' is not a 3-vector");
  for (int k = 0; k < 3; ++k) {
    double v;
    SLAPSE_RETURN_IF_ERROR(ReadNumber(node[k], what, &v));
    (*out)[k] = v;
  }
  return Status::Ok();
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

  std::ostringstream traj;
  traj << "# timestamp_s tx ty tz qx qy qz qw  (world_from_cam; world z up, road plane z = 0)\n";
  for (const GtFrame& f : gt.frames) {
    const Eigen::Vector3d& t = f.world_from_cam.translation;
    const Eigen::Quaterniond& q = f.world_from_cam.rotation;
    traj << Num(f.timestamp_s) << ' ' << Num(t.x()) << ' ' << Num(t.y()) << ' ' << Num(t.z()) << ' '
         << Num(q.x()) << ' ' << Num(q.y()) << ' ' << Num(q.z()) << ' ' << Num(q.w()) << '\n';
  }
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "trajectory_tum.txt", traj.str()));

  const Intrinsics& k = gt.intrinsics;
  std::ostringstream intr;
  intr << "{\n  \"fx_px\": " << Num(k.fx_px) << ",\n  \"fy_px\": " << Num(k.fy_px)
       << ",\n  \"cx_px\": " << Num(k.cx_px) << ",\n  \"cy_px\": " << Num(k.cy_px)
       << ",\n  \"width_px\": " << k.width_px << ",\n  \"height_px\": " << k.height_px << "\n}\n";
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "intrinsics.json", intr.str()));

  std::ostringstream planes;
  planes << "{\n  \"planes\": [";
  for (size_t i = 0; i < gt.planes.size(); ++i) {
    const GtPlane& p = gt.planes[i];
    planes << (i ? ",\n" : "\n") << "    {\"id\": " << p.id << ", \"kind\": \""
           << PlaneKindName(p.kind) << "\", \"normal_world\": " << Vec(p.normal_world)
           << ", \"distance_m\": " << Num(p.distance_m) << ",\n     \"polygons\": [";
    for (size_t j = 0; j < p.polygons_world.size(); ++j) {
      planes << (j ? ",\n       [" : "\n       [");
      for (size_t v = 0; v < p.polygons_world[j].size(); ++v) {
        planes << (v ? ", " : "") << Vec(p.polygons_world[j][v]);
      }
      planes << "]";
    }
    planes << "]}";
  }
  planes << "\n  ]\n}\n";
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "planes.json", planes.str()));

  std::ostringstream mb;
  mb << "# frame_index mb_cols mb_rows labels... (row-major; plane id >= 0, " << kMbSky << " sky, "
     << kMbClutter << " clutter, " << kMbMixed << " mixed)\n";
  for (size_t i = 0; i < gt.frames.size(); ++i) {
    mb << i << ' ' << gt.mb_cols << ' ' << gt.mb_rows;
    for (int l : gt.frames[i].mb_labels) mb << ' ' << l;
    mb << '\n';
  }
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "mb_labels.txt", mb.str()));

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
  SLAPSE_RETURN_IF_ERROR(WriteFile(root / "mb_mixed.txt", mixed.str()));

  // Minimal meta.json; SimulateDrive replaces it with a superset.
  std::ostringstream meta;
  meta << "{\n  \"fps\": " << Num(gt.fps) << ",\n  \"frames\": " << gt.frames.size()
       << ",\n  \"mb_cols\": " << gt.mb_cols << ",\n  \"mb_rows\": " << gt.mb_rows << "\n}\n";
  return WriteFile(root / "meta.json", meta.str());
}

StatusOr<GroundTruth> LoadGroundTruth(const std::string& dir) {
  const std::filesystem::path root(dir);
  GroundTruth gt;

  SLAPSE_RETURN_IF_ERROR(ReadJson(root / "intrinsics.json", [&](cv::FileStorage& fs) {
    Intrinsics& k = gt.intrinsics;
    SLAPSE_RETURN_IF_ERROR(ReadNumber(fs["fx_px"], "fx_px", &k.fx_px));
    SLAPSE_RETURN_IF_ERROR(ReadNumber(fs["fy_px"], "fy_px", &k.fy_px));
    SLAPSE_RETURN_IF_ERROR(ReadNumber(fs["cx_px"], "cx_px", &k.cx_px));
    SLAPSE_RETURN_IF_ERROR(ReadNumber(fs["cy_px"], "cy_px", &k.cy_px));
    double w, h;
    SLAPSE_RETURN_IF_ERROR(ReadNumber(fs["width_px"], "width_px", &w));
    SLAPSE_RETURN_IF_ERROR(ReadNumber(fs["height_px"], "height_px", &h));
    k.width_px = static_cast<int>(w);
    k.height_px = static_cast<int>(h);
    return Status::Ok();
  }));

  SLAPSE_RETURN_IF_ERROR(ReadJson(root / "planes.json", [&](cv::FileStorage& fs) {
    const cv::FileNode planes = fs["planes"];
    if (!planes.isSeq() && !planes.empty()) return DataLossError("'planes' is not a list");
    for (const cv::FileNode& node : planes) {
      GtPlane p;
      double id;
      SLAPSE_RETURN_IF_ERROR(ReadNumber(node["id"], "id", &id));
      p.id = static_cast<int>(id);
      const std::string kind = node["kind"].empty() ? "" : node["kind"].string();
      if (kind == "road") {
        p.kind = PlaneKind::kRoad;
      } else if (kind == "facade") {
        p.kind = PlaneKind::kFacade;
      } else if (kind == "background") {
        p.kind = PlaneKind::kBackground;
      } else {
        return DataLossError("plane " + std::to_string(p.id) + " has unknown kind '" + kind + "'");
      }
      SLAPSE_RETURN_IF_ERROR(ReadVec3(node["normal_world"], "normal_world", &p.normal_world));
      SLAPSE_RETURN_IF_ERROR(ReadNumber(node["distance_m"], "distance_m", &p.distance_m));
      const cv::FileNode polys = node["polygons"];
      if (!polys.empty() && !polys.isSeq()) return DataLossError("'polygons' is not a list");
      for (const cv::FileNode& poly : polys) {
        if (!poly.isSeq()) return DataLossError("a polygon is not a list");
        std::vector<Eigen::Vector3d> vs;
        for (const cv::FileNode& v : poly) {
          Eigen::Vector3d x;
          SLAPSE_RETURN_IF_ERROR(ReadVec3(v, "polygon vertex", &x));
          vs.push_back(x);
        }
        p.polygons_world.push_back(std::move(vs));
      }
      if (p.id != static_cast<int>(gt.planes.size())) {
        return DataLossError("planes.json: plane ids must be 0, 1, 2, ... in order");
      }
      gt.planes.push_back(std::move(p));
    }
    return Status::Ok();
  }));

  {
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
  }

  {
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
  }

  // Optional: drives simulated before mb_mixed.txt existed have no shares.
  if (const auto path = root / "mb_mixed.txt"; std::filesystem::exists(path)) {
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
  }

  // fps from meta.json, else from the timestamps.
  Status meta = ReadJson(root / "meta.json", [&](cv::FileStorage& fs) {
    return ReadNumber(fs["fps"], "fps", &gt.fps);
  });
  if (!meta.ok() && meta.code() != StatusCode::kNotFound) return meta;
  if (!meta.ok() && gt.frames.size() >= 2) {
    const double span = gt.frames.back().timestamp_s - gt.frames.front().timestamp_s;
    if (span > 0) gt.fps = (gt.frames.size() - 1) / span;
  }
  return gt;
}

}  // namespace slapse
