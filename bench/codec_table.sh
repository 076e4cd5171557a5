#!/usr/bin/env bash
# Table II per codec (issue 13): for each seed and each encoder preset
# (lab/codec EncoderPreset, `slapse simulate --preset`), simulate the same
# drive, run the offline pipeline and score it against the ground truth.
#   bench/codec_table.sh [SEEDS (default "1 2 3 4 5": tuning seeds)] [DURATION_S (default 5)]
#                        [PRESETS (default: the table's five)]
# Prints one row per (preset, seed): frames posed, ATE (m and % of distance),
# eps_D, and for re-encoded codecs the re-encode cost relative to bare decode
# (CPU time of the reading thread, so machine load does not inflate it).
# Needs a build (deploy/build.sh). Drives land in out/codec/<preset>/seed*/.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds=${1:-"1 2 3 4 5"}
duration=${2:-5}
presets=${3:-"mpeg2-ibbbp mpeg4-ibbbp h264-baseline-ippp-2s h264-high-bpyr-3ref hevc"}
slapse=${SLAPSE:-build/client/cli/slapse}
echo "| preset | drive | D (m) | frames posed | ATE (m) | ATE (% of D) | eps_D | re-encode / decode CPU |"
echo "|---|---|---:|---:|---:|---:|---:|---:|"
for preset in $presets; do
  for seed in $seeds; do
    dir=out/codec/$preset/seed$seed
    [ -f "$dir/meta.json" ] || "$slapse" simulate --out "$dir" --seed "$seed" \
      --duration-s "$duration" --preset "$preset" > /dev/null
    video=$(ls "$dir"/drive.* | head -1)
    out=$("$slapse" run "$video" --gt "$dir" --out "$dir/run" --quiet ${RUN_FLAGS:-} || true)
    frames=$(sed -n 's/^input .*, \([0-9]*\) frames).*/\1/p' <<< "$out")
    poses=$(sed -n 's/^tracked .*, \([0-9]*\) poses,.*/\1/p' <<< "$out")
    d=$(sed -n 's/^distance *\([0-9.]*\) m.*/\1/p' <<< "$out")
    epsD=$(sed -n 's/^eps_D *\([0-9.]*\) %.*/\1 %/p' <<< "$out")
    ate=$(sed -n 's/^ATE *\([0-9.]*\) m.*/\1/p' <<< "$out")
    pct=-
    if [ -n "$ate" ] && [ -n "$d" ]; then pct=$(awk -v a="$ate" -v d="$d" 'BEGIN{printf "%.2f %%", 100*a/d}'); fi
    cost=$(sed -n 's/^re-encoded from .*, \([0-9.]*x\) that).*/\1/p' <<< "$out")
    echo "| $preset | seed $seed | ${d:--} | ${poses:--} / ${frames:--} | ${ate:--} | $pct | ${epsD:--} | ${cost:--} |"
  done
done
