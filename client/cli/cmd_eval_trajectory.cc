// slapse eval-trajectory: the trajectory yardstick (docs/TRAJECTORY.md). The
// fixed drive list of lab/eval/drive_table.h (every scene kind; odd seeds
// tuning, even seeds reporting) is simulated with one encoder profile, run
// through the pipeline up to scale and with each metric scale source, and
// scored: a markdown report and a CSV, per split.
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>

#include <opencv2/core.hpp>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "core/common/timing.h"
#include "lab/eval/drive_eval.h"

namespace slapse::cli {
namespace {

// "all", "tuning", "reporting" or a comma list of drive names (rural-3, ...).
StatusOr<std::vector<DriveSpec>> SelectDrives(const std::string& which, int seeds_per_kind,
                                              const std::string& kinds) {
  std::vector<DriveSpec> drives;
  if (which == "all" || which == "tuning" || which == "reporting") {
    for (const DriveSpec& d : DriveTable(seeds_per_kind)) {
      if (which != "all" && DriveSplitName(d.split) != which) continue;
      if (!kinds.empty() &&
          ("," + kinds + ",").find("," + std::string(SceneKindName(d.kind)) + ",") ==
              std::string::npos) {
        continue;
      }
      drives.push_back(d);
    }
    return drives;
  }
  std::stringstream list(which);
  std::string name;
  while (std::getline(list, name, ',')) {
    auto d = ParseDriveName(name);
    if (!d.ok()) return d.status();
    drives.push_back(*d);
  }
  return drives;
}

Status WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::trunc);
  out << text;
  out.close();
  return out ? Status::Ok() : DataLossError("failed writing " + path);
}

}  // namespace

int RunEvalTrajectory(int argc, char** argv) {
  CommandLine cl("eval-trajectory", "[options]");
  CLI::App& app = cl.app();
  DriveEvalOptions eo;
  std::string drives_text = "all", kinds;
  int64_t seeds_per_kind = 8, jobs = 1;
  bool fresh = false;
  app.add_option("--drives", drives_text,
                 "all, tuning, reporting, or a list of drives (KIND-SEED, e.g. rural-3,urban-2)")
      ->type_name("WHICH")
      ->capture_default_str();
  app.add_option("--kinds", kinds,
                 "only these scene kinds (urban,avenue,rural,highway,plaza,intersection)")
      ->type_name("LIST");
  app.add_option("--seeds-per-kind", seeds_per_kind, "drives per scene kind (seeds 1..N)")
      ->type_name("N")
      ->capture_default_str();
  std::string profiles;
  for (const auto& n : EncoderProfileNames()) profiles += (profiles.empty() ? "" : ", ") + n;
  app.add_option("--profile", eo.profile, "encoder profile: " + profiles)
      ->type_name("NAME")
      ->capture_default_str();
  app.add_option("--out", eo.out_dir, "drives land in OUT/PROFILE/DRIVE, reports in OUT/PROFILE")
      ->type_name("DIR")
      ->capture_default_str();
  app.add_option("--jobs", jobs, "drives evaluated in parallel")
      ->type_name("N")
      ->capture_default_str();
  app.add_flag("--fresh", fresh, "simulate again even if a drive is on disk");
  // Ablation of the pipeline's default (the struct's default shown).
  AddTrackingFlags(&cl, &eo.pipeline);
  app.add_option("--refine-extra-sigma-px", eo.pipeline.refine.extra_sigma_px,
                 "added in quadrature to each vector's variance in the refinement "
                 "(WindowRefinerOptions::extra_sigma_px)")
      ->type_name("PX")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  // The method without the codec's errors (lab/eval/true_vectors.h).
  app.add_flag("--true-vectors", eo.true_vectors,
               "replace the codec's vectors of blocks on one plane by their true displacement");
  app.add_option("--true-vector-noise-px", eo.true_vector.noise_px,
                 "with --true-vectors: Gaussian noise added per axis")
      ->type_name("PX")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (!eo.true_vectors && eo.true_vector.noise_px != 0) {
    return Fail("eval-trajectory", "--true-vector-noise-px needs --true-vectors", 2);
  }
  if (!cl.positional().empty()) {
    return Fail("eval-trajectory", "unexpected argument '" + cl.positional()[0] + "'", 2);
  }
  for (const Status& s : {CheckRange("seeds-per-kind", seeds_per_kind, int64_t{1}, int64_t{1000}),
                          CheckRange("jobs", jobs, int64_t{1}, int64_t{64}),
                          CheckRange("refine-window", int64_t{eo.pipeline.refine.window_anchors},
                                     int64_t{3}, int64_t{30}),
                          eo.Check()}) {
    if (!s.ok()) return Fail("eval-trajectory", s.message(), 2);
  }
  eo.reuse = !fresh;
  auto drives = SelectDrives(drives_text, static_cast<int>(seeds_per_kind), kinds);
  if (!drives.ok()) return Fail("eval-trajectory", drives.status().message(), 2);
  if (drives->empty()) return Fail("eval-trajectory", "no drive selected", 2);
  if (jobs > 1) cv::setNumThreads(1);  // parallel over drives, not inside one

  const auto t0 = SteadyClock::now();
  std::vector<DriveResult> results(drives->size());
  std::vector<Status> errors(drives->size());
  std::atomic<size_t> next{0};
  std::mutex print;
  auto worker = [&] {
    for (size_t i; (i = next++) < drives->size();) {
      auto r = EvaluateDrive((*drives)[i], eo);
      std::lock_guard<std::mutex> lock(print);
      if (!r.ok()) {
        errors[i] = r.status();
        std::fprintf(stderr, "%s: %s\n", (*drives)[i].name.c_str(), r.status().ToString().c_str());
        continue;
      }
      results[i] = *r;
      std::fprintf(stderr, "%-16s %3d/%3d frames posed, ATE %.3f m, eps_D %.2f %% (%.0f s)\n",
                   r->spec.name.c_str(), r->posed_frames, r->frames, r->ate_m, 100 * r->eps_D,
                   r->simulate_s + r->evaluate_s);
    }
  };
  std::vector<std::thread> pool;
  for (int64_t j = 0; j < std::min<int64_t>(jobs, drives->size()); ++j) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  for (const Status& s : errors) {
    if (!s.ok()) return Fail("eval-trajectory", s.ToString());
  }
  const double wall_s = SecondsBetween(t0, SteadyClock::now());

  const std::string dir = eo.out_dir + "/" + eo.profile;
  std::filesystem::create_directories(dir);
  std::string md = DriveResultsMarkdown(results, eo.profile);
  if (eo.true_vectors) {  // never mistaken for a table of the codec's vectors
    char note[200];
    std::snprintf(note, sizeof note,
                  "**True vectors** (--true-vectors, noise %.2f px per axis): the codec's "
                  "vectors of blocks on one plane were replaced by their true displacement.\n\n",
                  eo.true_vector.noise_px);
    md = note + md;
  }
  for (const Status& s : {WriteText(dir + "/trajectory_eval.md", md),
                          WriteText(dir + "/trajectory_eval.csv", DriveResultsCsv(results))}) {
    if (!s.ok()) return Fail("eval-trajectory", s.ToString());
  }
  std::printf("%s\n%zu drives in %.0f s wall (%lld jobs); wrote %s/trajectory_eval.{md,csv}\n",
              md.c_str(), results.size(), wall_s, static_cast<long long>(jobs), dir.c_str());
  return 0;
}

}  // namespace slapse::cli
