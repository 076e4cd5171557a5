#!/usr/bin/env bash
# Configures and builds slapse into ./build (RelWithDebInfo). Extra arguments go to cmake,
# e.g. deploy/build.sh -DSLAPSE_SANITIZE=ON
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja "$@"
cmake --build build -j "$(nproc)"
