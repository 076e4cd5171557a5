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

// tum, kitti or quality, written page by page as the pages arrive: the
// export of a week-long session holds one page, not the week.
Status WriteTrajectoryPages(client::SlapseClient& client, const std::string& name,
                            const std::string& format, std::ostream& os, int64_t* poses) {
  if (format == "tum") WriteTrajectoryTumHeader(os);
  if (format == "quality") WritePoseQualityCsvHeader(os);
  return client.ForEachTrajectoryPage(name, [&](const v1::Trajectory& page) {
    if (format == "quality") {
      WritePoseQualityCsvRows(api::FramePosesFromProto(page), os);
    } else if (format == "tum") {
      WriteTrajectoryTumRows(api::TrajectoryFromProto(page), os);  // as Pipeline::poses()
    } else {
      WriteTrajectoryKitti(api::TrajectoryFromProto(page), os);
    }
    *poses += page.points_size();
    return static_cast<bool>(os);
  });
}

// json: one document (trajectory + plane map, run's planes.json schema), so
// it is built whole.
Status WriteJson(client::SlapseClient& client, const std::string& name, std::ostream& os,
                 int64_t* poses, int* planes) {
  auto trajectory = client.GetTrajectory(name);
  if (!trajectory.ok()) return trajectory.status();
  auto plane_map = client.GetPlaneMap(name);
  if (!plane_map.ok()) return plane_map.status();
  const auto traj = api::TrajectoryFromProto(*trajectory);
  ResultJsonOptions o;
  o.seen_at_frames = false;  // a server's plane map does not keep them
  o.trajectory = &traj;
  WriteResultJson(api::PlaneMapFromProto(*plane_map), trajectory->metric(), o, os);
  *poses = trajectory->points_size();
  *planes = plane_map->planes_size();
  return Status();
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

  Status fetched;  // the first failed rpc while writing, if any
  int64_t poses = 0;
  int planes = -1;
  auto write = [&](std::ostream& os) {
    if (format == "json") {
      fetched = WriteJson(*client, name, os, &poses, &planes);
    } else {
      fetched = WriteTrajectoryPages(*client, name, format, os, &poses);
    }
  };
  if (out == "-") {
    write(std::cout);
    std::cout.flush();
    if (!std::cout) return Fail("export", "cannot write to stdout");  // (pages stop: CANCELLED)
    if (!fetched.ok()) return Fail("export", fetched.ToString());
    return 0;
  }
  // Pages are written as they come into OUT.partial, renamed to OUT once the
  // last one is in: a failed export leaves no half file and an older OUT as it was.
  const std::string partial = out + ".partial";
  Status written = WriteResultFile(partial, write);
  if (written.ok() && fetched.ok()) {
    std::filesystem::rename(partial, out, ec);
    if (ec)
      written = UnavailableError("cannot rename " + partial + " to " + out + ": " + ec.message());
  }
  if (!written.ok() || !fetched.ok()) {
    std::filesystem::remove(partial, ec);
    if (!written.ok()) return Fail("export", written.message());
    return Fail("export", fetched.ToString() + " (" + out + " not written)");
  }
  const bool active =
      session->state() == v1::Session::CREATED || session->state() == v1::Session::RUNNING;
  std::printf("wrote %s: %lld poses%s of %s (%s%s)\n", out.c_str(), static_cast<long long>(poses),
              planes >= 0 ? (", " + std::to_string(planes) + " planes").c_str() : "", name.c_str(),
              v1::Session::State_Name(session->state()).c_str(),
              active ? ": a snapshot so far" : "");
  return 0;
}

}  // namespace slapse::cli
