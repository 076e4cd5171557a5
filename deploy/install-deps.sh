#!/usr/bin/env bash
# Installs every Debian 12 package slapse needs to build, test and run.
# Used by the README, .ci/run and the Dockerfile alike: keep this the single list.
#   install-deps.sh            everything: build, test, fuzz (development machines, CI)
#   install-deps.sh --build    what building slapse needs (the Dockerfile's build stage)
#   install-deps.sh --runtime  the shared libraries the built slapse binary loads, and
#                              nothing else (the Dockerfile's runtime stage)
#   install-deps.sh --camera   a simulated camera: ffmpeg (deploy/compose camera image)
#   install-deps.sh --prometheus   Prometheus (deploy/compose prometheus image)
#   install-deps.sh --haproxy  HAProxy (the k8s proxy image, deploy/k8s/proxy.yaml)
set -euo pipefail
MODE="${1:-all}"
case "$MODE" in
  all | --build | --runtime | --camera | --prometheus | --haproxy) ;;
  *) echo "install-deps: unknown mode '$MODE' (none, --build, --runtime, --camera, --prometheus, --haproxy)" >&2; exit 2 ;;
esac

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null 2>&1 || { echo "install-deps: run as root or install sudo" >&2; exit 1; }
  SUDO="sudo"
fi

BUILD_PACKAGES=(
  # toolchain
  build-essential cmake ninja-build pkg-config git ca-certificates
  # compiler cache: the Dockerfile's build stage keeps one across image builds
  ccache
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
  # service persistence: sessions, events, trajectories, plane maps (server/store.cc)
  libsqlite3-dev
  # service auth (server/auth.cc): OpenSSL's SHA-256 and constant-time compare for
  # bearer tokens
  libssl-dev
  # service: the HTTP server for /metrics (server/http_server.cc) and the Prometheus
  # metric registry and text format (server/metrics.cc)
  libcpp-httplib-dev prometheus-cpp-dev
  # service: RTSP push ingest on one port (server/rtsp_ingest.cc): gst-rtsp-server in
  # RECORD mode, its record pipeline's appsink (libgstreamer-plugins-base1.0-dev)
  libgstrtspserver-1.0-dev libgstreamer-plugins-base1.0-dev
)
TEST_PACKAGES=(
  # tests
  libgtest-dev libgmock-dev
  # tests: the openssl CLI makes the auth tests' CA and certificates
  openssl
  # tests: the real RTSP server the RTSP pull tests pull from (tests/rtsp_server.py):
  # GStreamer's gst-rtsp-server driven from Python; runs as root, unlike VLC.
  # tsdemux + mpegvideoparse are in plugins-bad, rtpmpvpay in plugins-good.
  python3-gi gir1.2-gst-rtsp-server-1.0
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-bad
  # tests: GStreamer's RTSP publisher (rtspclientsink) as a camera, besides ffmpeg
  gstreamer1.0-rtsp
  # fuzzing (fuzz/, docs/FUZZING.md): clang with libFuzzer + ASan/UBSan runtimes,
  # llvm-symbolizer for readable stacks
  clang-14 libclang-rt-14-dev llvm-14
  # tests: promtool checks the /metrics exposition; a real Prometheus scrapes a
  # real server in the `external` metrics test (tests/metrics_test.cc)
  prometheus
  # tests: the dashboard's browser test (tests/dashboard_test.cc) drives a real headless
  # Chromium with playwright-core from npm (tests/web/package-lock.json, `npm ci`)
  chromium nodejs
  # tests: the local cluster test (tests/cluster_test.cc, external) routes gRPC by
  # session owner through a real HAProxy (deploy/k8s/haproxy-cfg.sh)
  haproxy
)
# npm: Debian's package, unless the nodejs installed brings its own (NodeSource's does,
# and conflicts with Debian's npm).
if ! command -v npm >/dev/null 2>&1; then TEST_PACKAGES+=(npm); fi
# What the slapse binary loads at run time (ldd build/client/cli/slapse, each
# library's package): FFmpeg 5.1, OpenCV 4.6, gRPC 1.51 / protobuf 3.21.
RUNTIME_PACKAGES=(
  libavformat59 libavcodec59 libavutil57 libswscale6
  libopencv-core406 libopencv-imgproc406 libopencv-imgcodecs406 libopencv-calib3d406
  libgrpc++1.51 libgrpc29 libprotobuf32
  libcpp-httplib0.11 libprometheus-cpp-core1.0
  libsqlite3-0 libssl3 libceres3
  # RTSP push ingest: gst-rtsp-server and GStreamer (ldd), and the plugins its record
  # pipeline loads (dlopen, so the Dockerfile copies them by name): parsebin, appsink,
  # typefind (base), RTP depayloaders, rtpbin, udp (good), mpegtsmux and the video
  # parsers (bad)
  libgstrtspserver-1.0-0 libgstreamer1.0-0 libgstreamer-plugins-base1.0-0
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-bad
)
case "$MODE" in
  all) PACKAGES=("${BUILD_PACKAGES[@]}" "${TEST_PACKAGES[@]}") ;;
  --build) PACKAGES=("${BUILD_PACKAGES[@]}") ;;
  --runtime) PACKAGES=("${RUNTIME_PACKAGES[@]}") ;;
  --camera) PACKAGES=(ffmpeg) ;;
  --prometheus) PACKAGES=(prometheus) ;;
  --haproxy) PACKAGES=(haproxy) ;;
esac

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
