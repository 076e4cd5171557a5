#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, builds slapse and runs the whole test suite.
# This is the README's test command, and what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
bash deploy/build.sh -DSLAPSE_BUILD_TESTS=ON
ctest --test-dir build --output-on-failure --no-tests=error -j "$(nproc)" --timeout 600
