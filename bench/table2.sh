#!/usr/bin/env bash
# The paper's Table II on simulated drives: for each seed, simulate a drive of
# DURATION seconds (40-60 m at 25-50 km/h), run the offline pipeline on its
# MPEG-2 IBBBP video and score it against the ground truth.
#   bench/table2.sh [SEEDS (default "1 2 3 4 5")] [DURATION_S (default 5)]
# Needs a build (deploy/build.sh). Drives land in out/table2/seed*/.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds=${1:-"1 2 3 4 5"}
duration=${2:-5}
slapse=${SLAPSE:-build/client/cli/slapse}
echo "| drive | D (m) | eps_D | planes (>= 0.5 s) | eps_d (m) | eps_n (deg) | ATE (m) | RPE (m / deg) |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
for seed in $seeds; do
  dir=out/table2/seed$seed
  [ -f "$dir/meta.json" ] || "$slapse" simulate --out "$dir" --seed "$seed" --duration-s "$duration" > /dev/null
  out=$("$slapse" run "$dir/drive.ts" --gt "$dir" --out "$dir/run" --quiet || true)
  d=$(sed -n 's/^distance *\([0-9.]*\) m.*/\1/p' <<< "$out")
  epsD=$(sed -n 's/^eps_D *\([0-9.]*\) %.*/\1 %/p' <<< "$out")
  ate=$(sed -n 's/^ATE *\([0-9.]*\) m.*/\1/p' <<< "$out")
  rpe=$(sed -n 's/^RPE *\([0-9.]*\) m, \([0-9.]*\) deg.*/\1 \/ \2/p' <<< "$out")
  np=$(sed -n 's/^planes *\([0-9]*\) evaluated.*/\1/p' <<< "$out")
  epsd=$(sed -n 's/^planes.*eps_d \([0-9.]*\) m.*/\1/p' <<< "$out")
  epsn=$(sed -n 's/^planes.*eps_n \([0-9.]*\) deg.*/\1/p' <<< "$out")
  echo "| seed $seed | ${d:--} | ${epsD:--} | ${np:--} | ${epsd:--} | ${epsn:--} | ${ate:--} | ${rpe:--} |"
done
