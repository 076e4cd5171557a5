// The trajectory yardstick's fixed drive list (docs/TRAJECTORY.md, issue 12):
// every scene kind x seeds 1..N, each drive's camera, frame rate, resolution,
// speed and look a deterministic function of (kind, seed), and a fixed split:
// odd seeds are TUNING drives (choose settings on them), even seeds are
// REPORTING drives (report on them only; never tune on them).
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "lab/codec/video_encoder.h"
#include "lab/sim/simulate.h"

namespace slapse {

enum class DriveSplit { kTuning, kReporting };
const char* DriveSplitName(DriveSplit split);  // "tuning", "reporting"
// The split rule, in one place: odd seeds tune, even seeds report.
inline DriveSplit SplitOfSeed(int seed) {
  return seed % 2 == 1 ? DriveSplit::kTuning : DriveSplit::kReporting;
}

struct DriveSpec {
  SceneKind kind = SceneKind::kUrban;
  int seed = 1;  // 1..N within the kind
  DriveSplit split = DriveSplit::kTuning;
  std::string name;  // "<kind>-<seed>", e.g. "rural-3"
  // Everything but the encoder and the output directory.
  SimulateOptions sim;
};

// The drive (kind, seed), seed >= 1: simulator seed 1000 * (kind + 1) + seed
// (apart from Table II's seeds 1-10); fps {10, 25, 30, 60}, resolution
// {640x480, 1280x720, 1242x376 (KITTI's 1242x375 plus one row: 4:2:0 needs an
// even height)} cycled so that each kind's tuning and
// reporting seeds both cover them; camera height 1.2-2.5 m, pitch -10..+5 deg
// (up positive), the kind's speed range, supersampling 1-3, blur and sensor
// noise, appearance varied with the seed.
DriveSpec MakeDriveSpec(SceneKind kind, int seed);

// Every kind x seeds 1..seeds_per_kind, kind-major.
std::vector<DriveSpec> DriveTable(int seeds_per_kind = 8);

// Parses "rural-3" into its spec.
StatusOr<DriveSpec> ParseDriveName(const std::string& name);

// The encoder profiles the yardstick runs (the codec is a parameter):
//   mpeg2-ibbbp (default), mpeg4-ibbbp, h264-ibbbp, h264-ippp: GOP 12 frames;
//   MPEG quantiser 4, H.264 CRF 20 (slapse simulate's defaults);
//   and every camera-like preset of lab/codec EncoderPreset (e.g.
//   h264-baseline-ippp-2s, h264-high-bpyr-3ref, hevc), whose GOPs are in
//   seconds: fps is the drive's frame rate.
StatusOr<EncoderOptions> EncoderProfile(const std::string& name, double fps = 30.0);
std::vector<std::string> EncoderProfileNames();

}  // namespace slapse
