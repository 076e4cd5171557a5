// One drive of the trajectory yardstick end to end: simulate it (or reuse the
// simulation on disk), read its motion vectors once, run the pipeline up to
// scale and once per metric scale source (core/pipeline/pipeline.h
// ScaleOptions), score everything against the ground truth.
//
// Scale error of a source: the Sim(3) alignment's scale of that run's
// trajectory to the truth, minus 1 (0: metres are metres). Each source gets
// the truth it asks for: camera height = the true height; speed = the true
// speed at the up-to-scale run's first posed frame; first step = the true
// distance between its first two posed frames. A source that never made the
// run metric (e.g. no road tracked for the camera height) is "not metric".
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/pipeline/pipeline.h"
#include "lab/eval/drive_table.h"
#include "lab/eval/true_vectors.h"

namespace slapse {

struct DriveEvalOptions {
  std::string out_dir = "out/trajectory_eval";  // drives land in out_dir/<profile>/<name>/
  std::string profile = "mpeg2-ibbbp";          // EncoderProfile
  bool reuse = true;                            // keep a drive already simulated
  PipelineOptions pipeline;                     // the scale source is set per run
  // Run on true vectors instead of the codec's (lab/eval/true_vectors.h):
  // the method's own error, without the codec's. Off by default.
  bool true_vectors = false;
  TrueVectorOptions true_vector;
  Status Check() const;
};

enum ScaleSourceIndex { kScaleCameraHeight = 0, kScaleSpeed = 1, kScaleFirstStep = 2 };
constexpr int kNumScaleSources = 3;

struct DriveResult {
  DriveSpec spec;
  int frames = 0;
  int posed_frames = 0;           // frames with a pose, anchors and between (up to scale run)
  int64_t first_pose_frame = -1;  // -1: never
  double first_pose_s = -1.0;
  int anchor_pairs = 0, tracked_pairs = 0;
  int motion_only_anchors = 0;  // tracked anchors without a plane (PoseKind::kMotionOnly)
  int coasting_anchors = 0;     // tracked anchors the motion model posed (PoseKind::kCoasting)
  int extended_pairs = 0;       // pairs handed back for a longer baseline (PipelineStep::extended)
  // Pairs whose motion took the full path (PipelineStep::motion_path
  // kFullFit): the pipeline's costliest stage, docs/BENCHMARKS.md "Session 31".
  int full_motion_fits = 0;
  ScaleSupport scale_support;  // how many anchor steps a plane measured (Pipeline::scale_support)
  double drive_distance_m = 0.0;  // the true path, whole drive
  bool evaluated = false;         // >= 3 poses: the errors below are valid
  double distance_m = 0.0;        // the true path over the posed frames
  // ATE over every posed frame; ATE over the anchors only; eps_D (paper: the
  // anchors, first-step scale) and RPE per anchor step.
  double ate_m = 0.0, anchor_ate_m = 0.0, eps_D = 0.0, rpe_m = 0.0, rpe_deg = 0.0;
  int planes_evaluated = 0;
  double eps_d_m = -1.0, eps_n_deg = -1.0;  // -1: no plane evaluated
  bool metric[kNumScaleSources] = {false, false, false};
  double scale_error[kNumScaleSources] = {0, 0, 0};  // valid where metric[] and evaluated
  // The camera-height run's Pipeline::height_road_depression_deg (NaN when it
  // did not become metric): how steeply its image saw the road.
  double height_road_depression_deg = NAN;
  std::string note;  // the most frequent reason a pair did not track (extended pairs aside)
  double simulate_s = 0.0, evaluate_s = 0.0;  // wall time
};

StatusOr<DriveResult> EvaluateDrive(const DriveSpec& spec, const DriveEvalOptions& options);

// CSV (header + one row a drive) and the markdown report (per split: a table
// and its medians / worst).
std::string DriveResultsCsv(const std::vector<DriveResult>& results);
std::string DriveResultsMarkdown(const std::vector<DriveResult>& results,
                                 const std::string& profile);

}  // namespace slapse
