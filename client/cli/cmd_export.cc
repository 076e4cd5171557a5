// slapse export: a session's trajectory and plane map from a server
// (GetTrajectory, GetPlaneMap) in the files `slapse run` writes, through the
// same writers (core/pipeline/result_io.h): equal results, equal bytes.
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "api/convert.h"
#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "client/lib/client.h"
#include "core/pipeline/result_io.h"

namespace slapse::cli {
namespace {

// The file `slapse run` writes for each format, used when --out is a directory.
const char* DefaultFileName(const std::string& format) {
  if (format == "tum") return "trajectory_tum.txt";
  if (format == "kitti") return "trajectory_kitti.txt";
  if (format == "quality") return "trajectory_quality.csv";
  return "session.json";
}

}  // namespace

int RunExport(int argc, char** argv) {
  CommandLine cl("export",
                 "SESSION [options]   (the session's trajectory / plane map so far, as slapse run "
                 "writes them)",
                 "SESSION");
  CLI::App& app = cl.app();
  std::string server, format = "json", out = "-";
  AddServerFlag(&cl, &server);
  app.add_option("--format", format,
                 "tum or kitti (trajectory, as run's trajectory_*.txt), json (trajectory + planes, "
                 "run's planes.json schema), quality (one row per pose, as run's "
                 "trajectory_quality.csv)")
      ->type_name("FMT")
      ->capture_default_str();
  app.add_option("--out", out,
                 "file to write, '-' for stdout, or a directory (gets trajectory_tum.txt, "
                 "trajectory_kitti.txt, trajectory_quality.csv or session.json)")
      ->type_name("PATH")
      ->capture_default_str();
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (cl.positional().size() != 1) {
    return Fail("export",
                "expected one SESSION, e.g. sessions/3k7q... as create printed it (see --help)", 2);
  }
  if (format != "tum" && format != "kitti" && format != "json" && format != "quality") {
    return Fail("export", "--format must be tum, kitti, json or quality, not '" + format + "'", 2);
  }
  std::error_code ec;
  if (out != "-" && std::filesystem::is_directory(out, ec)) {
    out = (std::filesystem::path(out) / DefaultFileName(format)).string();
  }

  const std::string name = cl.positional()[0];
  auto connection = ServerConnection();
  if (!connection.ok()) return Fail("export", connection.status().message(), 2);
  auto client = client::SlapseClient::Connect(server, *connection);
  auto session = client->GetSession(name);
  if (!session.ok()) return Fail("export", session.status().ToString());
  auto trajectory = client->GetTrajectory(name);
  if (!trajectory.ok()) return Fail("export", trajectory.status().ToString());
  v1::PlaneMap plane_map;
  if (format == "json") {
    auto got = client->GetPlaneMap(name);
    if (!got.ok()) return Fail("export", got.status().ToString());
    plane_map = std::move(*got);
  }

  const auto traj = api::TrajectoryFromProto(*trajectory);  // as Pipeline::poses()
  auto write = [&](std::ostream& os) {
    if (format == "tum") {
      WriteTrajectoryTum(traj, os);
    } else if (format == "kitti") {
      WriteTrajectoryKitti(traj, os);
    } else if (format == "quality") {
      WritePoseQualityCsv(api::FramePosesFromProto(*trajectory), os);
    } else {
      ResultJsonOptions o;
      o.seen_at_frames = false;  // a server's plane map does not keep them
      o.trajectory = &traj;
      WriteResultJson(api::PlaneMapFromProto(plane_map), trajectory->metric(), o, os);
    }
  };
  if (out == "-") {
    write(std::cout);
    std::cout.flush();
    if (!std::cout) return Fail("export", "cannot write to stdout");
    return 0;
  }
  if (Status s = WriteResultFile(out, write); !s.ok()) return Fail("export", s.message());
  const bool active =
      session->state() == v1::Session::CREATED || session->state() == v1::Session::RUNNING;
  std::printf(
      "wrote %s: %d poses%s of %s (%s%s)\n", out.c_str(), trajectory->points_size(),
      format == "json" ? (", " + std::to_string(plane_map.planes_size()) + " planes").c_str() : "",
      name.c_str(), v1::Session::State_Name(session->state()).c_str(),
      active ? ": a snapshot so far" : "");
  return 0;
}

}  // namespace slapse::cli
