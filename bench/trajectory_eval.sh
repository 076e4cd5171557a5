#!/usr/bin/env bash
# The trajectory yardstick (docs/TRAJECTORY.md, issue 12): the fixed list of
# 48 drives (6 scene kinds x seeds 1-8; odd seeds TUNING, even seeds
# REPORTING), simulated once per encoder profile, run through the pipeline
# up to scale and with each metric scale source, scored against the truth.
#   bench/trajectory_eval.sh [PROFILE (default mpeg2-ibbbp)] [JOBS (default: nproc)] [extra flags]
# PROFILE: mpeg2-ibbbp, mpeg4-ibbbp, h264-ibbbp, h264-ippp.
# Extra flags go to `slapse eval-trajectory` (e.g. --drives reporting,
# --kinds rural,highway, --fresh). Drives land in out/trajectory_eval/PROFILE/
# (reused on the next run: only the pipeline runs again), the report in
# out/trajectory_eval/PROFILE/trajectory_eval.{md,csv}.
# Needs a build (deploy/build.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
profile=${1:-mpeg2-ibbbp}
jobs=${2:-$(nproc)}
shift $(( $# < 2 ? $# : 2 ))
slapse=${SLAPSE:-build/client/cli/slapse}
exec "$slapse" eval-trajectory --profile "$profile" --jobs "$jobs" "$@"
