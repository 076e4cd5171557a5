#!/usr/bin/env bash
# The main job end to end on a fresh Debian 12 machine: install, build, simulate a
# street drive (MPEG-2 IBBBP), read its motion vectors back and draw them, then run
# SLAPSE on the video: trajectory, plane map, top-down plot, errors against the truth.
# Output lands in ./out/demo (override with OUT=dir).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/demo}
bash deploy/install-deps.sh
bash deploy/build.sh -DSLAPSE_BUILD_TESTS=OFF
slapse=build/client/cli/slapse
"$slapse" simulate --out "$OUT" --seed 1 --codec mpeg2 --gop IBBBP --duration-s 10
"$slapse" mvs "$OUT/drive.ts" --draw 30 --png "$OUT/mv_overlay.png" --csv "$OUT/mvs.csv"
"$slapse" run "$OUT/drive.ts" --gt "$OUT" --out "$OUT/run" --quiet
echo "demo: wrote $OUT (video, ground truth, mvs.csv, mv_overlay.png, run/{trajectory_tum.txt, trajectory_kitti.txt, planes.json, map.png})"
