#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, builds slapse and runs the whole test suite.
# This is the README's test command, and what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
# Line tables only: full debug info would need GBs of disk for the ~60 binaries.
bash deploy/build.sh -DSLAPSE_BUILD_TESTS=ON -DSLAPSE_DEBUG_INFO=lines
# Fuzz smoke (docs/FUZZING.md): every libFuzzer harness for FUZZ_SECONDS
# (default 60) in a clang build tree of its own, two at a time; fails on any
# crash, leak, UB report or invariant violation.
PARALLEL=2 bash fuzz/run.sh "${FUZZ_SECONDS:-60}"
# The test suite last, so its summary closes the output.
ctest --test-dir build --output-on-failure --no-tests=error -j "$(nproc)" --timeout 600
