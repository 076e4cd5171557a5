#include "core/pipeline/result_io.h"

#include <cstdio>
#include <fstream>

#include "core/common/json_io.h"

namespace slapse {

void WriteTrajectoryTum(const std::vector<TimedPose>& trajectory, std::ostream& out) {
  WriteTrajectoryTumHeader(out);
  WriteTrajectoryTumRows(trajectory, out);
}

void WriteTrajectoryTumHeader(std::ostream& out) {
  out << "# timestamp_s tx ty tz qx qy qz qw  (world_from_cam; world = first tracked camera, "
         "x right, y down, z forward)\n";
}

void WriteTrajectoryTumRows(const std::vector<TimedPose>& trajectory, std::ostream& out) {
  char line[400];
  for (const auto& p : trajectory) {
    const Eigen::Quaterniond& q = p.world_from_cam.rotation;
    const Eigen::Vector3d& t = p.world_from_cam.translation;
    std::snprintf(line, sizeof(line), "%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", p.timestamp_s,
                  t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
    out << line;
  }
}

void WriteTrajectoryKitti(const std::vector<TimedPose>& trajectory, std::ostream& out) {
  char line[400];
  for (const auto& p : trajectory) {
    const Eigen::Vector3d& t = p.world_from_cam.translation;
    const Eigen::Matrix3d R = p.world_from_cam.R();
    std::snprintf(line, sizeof(line),
                  "%.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", R(0, 0), R(0, 1),
                  R(0, 2), t.x(), R(1, 0), R(1, 1), R(1, 2), t.y(), R(2, 0), R(2, 1), R(2, 2),
                  t.z());
    out << line;
  }
}

std::vector<TimedPose> TimedPosesOf(const std::vector<FramePose>& poses) {
  std::vector<TimedPose> out;
  out.reserve(poses.size());
  for (const FramePose& p : poses) out.push_back(p.pose);
  return out;
}

void WritePoseQualityCsv(const std::vector<FramePose>& poses, std::ostream& out) {
  WritePoseQualityCsvHeader(out);
  WritePoseQualityCsvRows(poses, out);
}

void WritePoseQualityCsvHeader(std::ostream& out) {
  out << "frame_index,timestamp_s,kind,position_sigma,inliers,rms_px,revision,gap_frames,note\n";
}

void WritePoseQualityCsvRows(const std::vector<FramePose>& poses, std::ostream& out) {
  char line[200];
  for (const FramePose& p : poses) {
    const PoseQuality& q = p.quality;
    std::snprintf(line, sizeof(line), "%lld,%.6f,%s,%.6g,%d,%.3f,%d,%lld,",
                  static_cast<long long>(p.pose.index), p.pose.timestamp_s, PoseKindName(q.kind),
                  q.position_sigma, q.inliers, q.rms_px, p.revision,
                  static_cast<long long>(q.gap_frames));
    std::string note = q.note;
    for (char& c : note) {
      if (c == '"' || c == '\n') c = '\'';
    }
    out << line << '"' << note << "\"\n";
  }
}

namespace {

// planes.json's numbers have always had fixed decimals by member: these keep
// its bytes (nlohmann alone would print shortest round-trip forms).
std::string ResultNumber(const std::string& key, size_t /*index*/, double v) {
  if (key == "t" || key == "q") return FormatDouble("%.9f", v);
  if (key == "first_seen_s" || key == "last_seen_s") return FormatDouble("%.3f", v);
  return FormatDouble("%.6f", v);  // timestamp_s, normal_world, distance
}

}  // namespace

void WriteResultJson(const std::map<int, MapPlane>& planes, bool metric,
                     const ResultJsonOptions& options, std::ostream& out) {
  Json doc;
  doc["frame"] = "world = first tracked camera (x right, y down, z forward); n . X = d";
  doc["unit"] = metric ? "m" : "first step";
  if (options.trajectory != nullptr) {
    Json& trajectory = doc["trajectory"] = Json::array();
    for (const auto& p : *options.trajectory) {
      const Eigen::Quaterniond& q = p.world_from_cam.rotation;
      const Eigen::Vector3d& t = p.world_from_cam.translation;
      Json pose;
      pose["frame_index"] = static_cast<long long>(p.index);
      pose["timestamp_s"] = p.timestamp_s;
      pose["t"] = {t.x(), t.y(), t.z()};
      pose["q"] = {q.x(), q.y(), q.z(), q.w()};
      trajectory.push_back(std::move(pose));
    }
  }
  Json& list = doc["planes"] = Json::array();
  for (const auto& [id, p] : planes) {
    Json plane;
    plane["track_id"] = id;
    plane["normal_world"] = {p.normal_world.x(), p.normal_world.y(), p.normal_world.z()};
    plane["distance"] = p.distance_m;
    plane["first_seen_s"] = p.first_seen_s;
    plane["last_seen_s"] = p.last_seen_s;
    plane["updates"] = p.observations;
    if (options.seen_at_frames) plane["seen_at_frames"] = p.seen_indices;
    list.push_back(std::move(plane));
  }
  out << DumpJson(doc, ResultNumber);
}

Status WriteResultFile(const std::string& path, const std::function<void(std::ostream&)>& write) {
  std::ofstream out(path);
  if (!out) return UnavailableError("cannot write " + path);
  write(out);
  out.flush();
  if (!out) return UnavailableError("error writing " + path);
  return Status::Ok();
}

}  // namespace slapse
