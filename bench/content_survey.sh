#!/usr/bin/env bash
# Which content costs the pipeline most, relative to decoding it (issue 17:
# "<= 1.3x bare decode on any content; report the worst").
# For every drive directory under ROOT (a drive.* video, and intrinsics.json
# and the ground truth beside it, as `slapse eval-trajectory` and
# `slapse simulate` leave them), runs build/bench/slapse_bench on it and
# prints one Markdown row per drive, the costliest first: frames, bare
# decode frames/s and the pipeline's x bare decode (in-process wall time,
# best of REPEAT runs; slapse_bench reads the intrinsics from the drive's
# ground truth).
#   bench/content_survey.sh [ROOT (default out/trajectory_eval)] [REPEAT (default 1)]
# e.g. after `bench/trajectory_eval.sh mpeg2-ibbbp 2 --drives tuning --seeds-per-kind 16`:
#   bench/content_survey.sh out/trajectory_eval/mpeg2-ibbbp
# Wall time on a shared machine is noisy: confirm the worst rows with
# callgrind (docs/BENCHMARKS.md "Session 31"). Needs a build (deploy/build.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
root=${1:-out/trajectory_eval}
repeat=${2:-1}
bench=${SLAPSE_BENCH:-build/bench/slapse_bench}
rows=()
while IFS= read -r meta; do
  dir=$(dirname "$meta")
  video=$(ls "$dir"/drive.* 2> /dev/null | head -1 || true)
  [ -n "$video" ] || continue
  table=$("$bench" --input "$video" --repeat "$repeat")
  # | stage | frames | seconds | frames/s | x bare decode | peak RSS (MiB) |
  bare=$(awk -F'|' '/^\| bare FFmpeg decode/ {gsub(/ /, "", $5); print $5}' <<< "$table")
  row=$(awk -F'|' '/^\| SLAPSE pipeline \(reader/ {gsub(/ /, "", $3); gsub(/ /, "", $6);
                    print $3 " " $6}' <<< "$table")
  [ -n "$bare" ] && [ -n "$row" ] || { echo "content_survey: no table for $video" >&2; exit 1; }
  read -r frames ratio <<< "$row"
  rows+=("$ratio|${dir#"$root"/}|$frames|$bare")
done < <(find -L "$root" -name meta.json | sort)
[ ${#rows[@]} -gt 0 ] || { echo "content_survey: no drives under $root" >&2; exit 1; }
echo "| drive | frames | bare decode (frames/s) | pipeline (x bare decode) |"
echo "|---|---:|---:|---:|"
printf '%s\n' "${rows[@]}" | sort -t'|' -k1,1 -g -r |
  awk -F'|' '{printf "| %s | %s | %s | %s |\n", $2, $3, $4, $1}'
