#include "core/pipeline/result_io.h"

#include <cstdio>
#include <fstream>

namespace slapse {

void WriteTrajectoryTum(const std::vector<Pipeline::TrajectoryPoint>& trajectory,
                        std::ostream& out) {
  out << "# timestamp_s tx ty tz qx qy qz qw  (world_from_cam; world = first tracked camera, "
         "x right, y down, z forward)\n";
  char line[400];
  for (const auto& p : trajectory) {
    const Eigen::Quaterniond& q = p.world_from_cam.rotation;
    const Eigen::Vector3d& t = p.world_from_cam.translation;
    std::snprintf(line, sizeof(line), "%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", p.timestamp_s,
                  t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
    out << line;
  }
}

void WriteTrajectoryKitti(const std::vector<Pipeline::TrajectoryPoint>& trajectory,
                          std::ostream& out) {
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

void WriteResultJson(const std::map<int, MapPlane>& planes, bool metric,
                     const ResultJsonOptions& options, std::ostream& out) {
  out << "{\n  \"frame\": \"world = first tracked camera (x right, y down, z forward); n . X = "
         "d\",\n"
      << "  \"unit\": \"" << (metric ? "m" : "first step") << "\",\n";
  char buf[400];
  if (options.trajectory != nullptr) {
    out << "  \"trajectory\": [";
    bool first = true;
    for (const auto& p : *options.trajectory) {
      const Eigen::Quaterniond& q = p.world_from_cam.rotation;
      const Eigen::Vector3d& t = p.world_from_cam.translation;
      std::snprintf(buf, sizeof(buf),
                    "%s    {\"frame_index\": %lld, \"timestamp_s\": %.6f, \"t\": [%.9f, %.9f, "
                    "%.9f], \"q\": [%.9f, %.9f, %.9f, %.9f]}",
                    first ? "\n" : ",\n", static_cast<long long>(p.index), p.timestamp_s, t.x(),
                    t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
      out << buf;
      first = false;
    }
    out << "\n  ],\n";
  }
  out << "  \"planes\": [";
  bool first = true;
  for (const auto& [id, p] : planes) {
    out << (first ? "\n" : ",\n");
    first = false;
    std::snprintf(
        buf, sizeof(buf),
        "    {\"track_id\": %d, \"normal_world\": [%.6f, %.6f, %.6f], \"distance\": %.6f, "
        "\"first_seen_s\": %.3f, \"last_seen_s\": %.3f, \"updates\": %d",
        id, p.normal_world.x(), p.normal_world.y(), p.normal_world.z(), p.distance_m,
        p.first_seen_s, p.last_seen_s, p.observations);
    out << buf;
    if (options.seen_at_frames) {
      out << ", \"seen_at_frames\": [";
      for (size_t i = 0; i < p.seen_indices.size(); ++i) {
        out << (i ? ", " : "") << p.seen_indices[i];
      }
      out << "]";
    }
    out << "}";
  }
  out << "\n  ]\n}\n";
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
