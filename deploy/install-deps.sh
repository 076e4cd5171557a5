#!/usr/bin/env bash
# Installs every Debian 12 package slapse needs to build, test and run.
# Used by the README, .ci/run and the Dockerfile alike: keep this the single list.
set -euo pipefail

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null 2>&1 || { echo "install-deps: run as root or install sudo" >&2; exit 1; }
  SUDO="sudo"
fi

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build pkg-config git ca-certificates
  # FFmpeg: decoding with exported motion vectors, encoding (mpeg2video, mpeg4, libx264)
  libavformat-dev libavcodec-dev libavutil-dev libswscale-dev ffmpeg
  # maths and vision
  libeigen3-dev libopencv-dev
  # sliding-window refinement (core/refine): Ceres Solver, Levenberg-Marquardt with autodiff
  libceres-dev
  # parsing: CLI flags (CLI11) and JSON files (nlohmann-json), header-only
  libcli11-dev nlohmann-json3-dev
  # service
  libgrpc++-dev libprotobuf-dev protobuf-compiler protobuf-compiler-grpc
  # tests
  libgtest-dev libgmock-dev
  # tests: the real RTSP server the RTSP pull tests pull from (tests/rtsp_server.py):
  # GStreamer's gst-rtsp-server driven from Python; runs as root, unlike VLC.
  # tsdemux + mpegvideoparse are in plugins-bad, rtpmpvpay in plugins-good.
  python3-gi gir1.2-gst-rtsp-server-1.0
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-bad
  # fuzzing (fuzz/, docs/FUZZING.md): clang with libFuzzer + ASan/UBSan runtimes,
  # llvm-symbolizer for readable stacks
  clang-14 libclang-rt-14-dev llvm-14
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
