#!/usr/bin/env bash
# Runs every libFuzzer harness in fuzz/ for SECONDS each (docs/FUZZING.md).
#   bash fuzz/run.sh SECONDS [HARNESS ...]     e.g. bash fuzz/run.sh 60
# Builds build-fuzz/ (clang-14, -DSLAPSE_FUZZ=ON) if needed. Each harness runs
# in one process (no -jobs: one core each), from its seeds in fuzz/corpus/<name> plus the
# corpus it grew in earlier runs (build-fuzz/fuzz-work/<name>/corpus). Prints
# per harness: executions, exec/s, coverage (cov = edges, ft = features) and
# the crashes / leaks / UB / timeouts found (artifacts are kept in
# build-fuzz/fuzz-work/<name>/). Exits non-zero if any harness found one.
# Environment: BUILD_DIR (default build-fuzz), PARALLEL (harnesses at once, default 1).
set -uo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${1:?usage: fuzz/run.sh SECONDS_PER_HARNESS [HARNESS ...]}
shift
BUILD_DIR=${BUILD_DIR:-build-fuzz}
PARALLEL=${PARALLEL:-1}
ALL=(mv_reader sdp_url intrinsics upload_queue session_proto)
HARNESSES=("${@:-${ALL[@]}}")

if [ ! -f "$BUILD_DIR/build.ninja" ]; then
  CC=clang-14 CXX=clang++-14 cmake -S . -B "$BUILD_DIR" -G Ninja -DSLAPSE_FUZZ=ON \
    -DSLAPSE_BUILD_TESTS=OFF -DSLAPSE_DEBUG_INFO=lines ${CMAKE_CXX_COMPILER_LAUNCHER:+-DCMAKE_CXX_COMPILER_LAUNCHER=$CMAKE_CXX_COMPILER_LAUNCHER} \
    > "$BUILD_DIR.configure.log" 2>&1 || { cat "$BUILD_DIR.configure.log"; exit 2; }
fi
cmake --build "$BUILD_DIR" -j"$(nproc)" --target slapse_fuzz || exit 2

# Extra flags per harness: the MV reader decodes whole (small) streams.
flags_for() {
  case "$1" in
    mv_reader) echo "-max_len=262144 -timeout=25 -rss_limit_mb=3072" ;;
    sdp_url) echo "-max_len=8192 -timeout=10" ;;
    *) echo "-max_len=4096 -timeout=10" ;;
  esac
}

run_one() {
  local name=$1 work="$BUILD_DIR/fuzz-work/$1"
  mkdir -p "$work/corpus"
  rm -f "$work"/{crash,leak,timeout,oom,slow-unit}-* "$work/log"
  # shellcheck disable=SC2046
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    "$BUILD_DIR/fuzz/fuzz_$name" -max_total_time="$SECONDS_EACH" \
    -print_final_stats=1 -artifact_prefix="$work/" $(flags_for "$name") \
    "$work/corpus" "fuzz/corpus/$name" > "$work/log" 2>&1
  echo $? > "$work/rc"
}

i=0
for name in "${HARNESSES[@]}"; do
  run_one "$name" &
  i=$((i + 1))
  if [ $((i % PARALLEL)) -eq 0 ]; then wait; fi
done
wait

failed=0
printf '%-16s %12s %9s %7s %7s %8s\n' harness execs exec/s cov ft findings
for name in "${HARNESSES[@]}"; do
  work="$BUILD_DIR/fuzz-work/$name"
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/log" | grep -o '[0-9]*$' | tail -1)
  rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$work/log" | grep -o '[0-9]*$' | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$work/log" | tail -1 | grep -o '[0-9]*')
  ft=$(grep -o 'ft: [0-9]*' "$work/log" | tail -1 | grep -o '[0-9]*')
  findings=$(find "$work" -maxdepth 1 -name 'crash-*' -o -maxdepth 1 -name 'leak-*' \
             -o -maxdepth 1 -name 'timeout-*' -o -maxdepth 1 -name 'oom-*' | wc -l)
  rc=$(cat "$work/rc")
  [ "$rc" != 0 ] && [ "$findings" = 0 ] && findings=1  # died without an artifact
  printf '%-16s %12s %9s %7s %7s %8s\n' "$name" "${execs:-?}" "${rate:-?}" "${cov:-?}" \
    "${ft:-?}" "$findings"
  if [ "$findings" != 0 ]; then
    failed=1
    echo "--- $name: exit $rc; log $work/log; artifacts:" >&2
    find "$work" -maxdepth 1 \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' -o -name 'oom-*' \) >&2
    grep -m1 -A25 -E 'ERROR:|runtime error|invariant violated' "$work/log" >&2
  fi
done
exit $failed
