#!/usr/bin/env bash
# Builds the slapse image with podman and smoke-tests it for real (docs/DEPLOY.md):
#   1. the image: size, runs as the non-root user, /var/lib/slapse is a writable volume
#   2. serve (JSON logs), the HEALTHCHECK (slapse health -> SERVING), /metrics
#   3. a simulated drive (simulated by the image) uploaded from a client container,
#      watched to FINISHED, its trajectory exported and compared byte for byte with
#      offline `slapse run` on the same file (also in the image)
# Minutes, not seconds (an image build), so it is not part of CI's test command.
# Needs root (podman). Env: IMAGE (default slapse:test), GRPC_PORT / HTTP_PORT
# (default: free ports; the sandbox's containers share the host network),
# CONTAINER_BASE (the script that readies podman and the debian:12 base image).
set -euo pipefail
cd "$(dirname "$0")/.."
IMAGE=${IMAGE:-slapse:test}
NAME=slapse-container-test-$$
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
GRPC_PORT=${GRPC_PORT:-$(free_port)}
HTTP_PORT=${HTTP_PORT:-$(free_port)}
step() { echo "== $(date -u +%H:%M:%S) $*"; }
fail() { echo "container-test: FAIL: $*" >&2; podman logs "$NAME" 2>&1 | tail -20 >&2 || true; exit 1; }

# 0. podman and the debian:12 base image (built from Debian's packages, no registry).
base=${CONTAINER_BASE:-}
if [ -z "$base" ]; then
  for c in ../shared/tools/container-base.sh ../../shared/tools/container-base.sh /work/shared/tools/container-base.sh; do
    [ -f "$c" ] && { base=$c; break; }
  done
fi
[ -n "$base" ] || fail "container-base.sh not found (set CONTAINER_BASE)"
step "container base: $base"
bash "$base"

step "podman build --format docker -t $IMAGE ."
t0=$(date +%s)
podman build --format docker -t "$IMAGE" . >/tmp/container-test-build.log 2>&1 \
  || { tail -30 /tmp/container-test-build.log >&2; fail "image build (log: /tmp/container-test-build.log)"; }
size=$(podman image inspect --format '{{.Size}}' "$IMAGE")
base_size=$(podman image inspect --format '{{.Size}}' docker.io/library/debian:12)
echo "image $IMAGE: $((size / 1000000)) MB (debian:12 base: $((base_size / 1000000)) MB), built in $(($(date +%s) - t0)) s"
podman history --format '{{.Size}}\t{{.CreatedBy}}' "$IMAGE" | cut -c1-110 | head -12

step "1. user, volume, health check in the image"
[ "$(podman run --rm --no-healthcheck --entrypoint id "$IMAGE" -u)" = 10001 ] || fail "the image does not run as uid 10001"
podman image inspect --format '{{json .Config.Volumes}} {{json .Config.Healthcheck.Test}}' "$IMAGE"
podman run --rm --no-healthcheck --entrypoint sh "$IMAGE" -c 'touch /var/lib/slapse/probe && echo "/var/lib/slapse writable by $(id -un)"' \
  || fail "/var/lib/slapse is not writable by the slapse user"
# nothing of the toolchain in the runtime image
for tool in gcc c++ cmake protoc; do
  podman run --rm --no-healthcheck --entrypoint sh "$IMAGE" -c "! command -v $tool" >/dev/null || fail "$tool is in the runtime image"
done

WORK=$(mktemp -d /tmp/container-test.XXXXXX)
chmod 777 "$WORK"
cleanup() { podman rm -f "$NAME" >/dev/null 2>&1 || true; podman volume rm -f "$NAME-data" >/dev/null 2>&1 || true; }
trap cleanup EXIT
slapse_run() { podman run --rm --no-healthcheck -v "$WORK:/work:z" -w /work "$IMAGE" "$@"; }

step "2. serve: gRPC :$GRPC_PORT, HTTP :$HTTP_PORT, JSON logs, data volume"
podman volume create "$NAME-data" >/dev/null
# The image's HEALTHCHECK asks 127.0.0.1:50051; this sandbox shares the host network,
# so the server runs on a free port and the same check is given that port.
check=$(podman image inspect --format '{{join .Config.Healthcheck.Test " "}}' "$IMAGE" | sed "s/^CMD //; s/:50051 /:$GRPC_PORT /")
echo "health check: $check"
podman run -d --name "$NAME" -v "$NAME-data:/var/lib/slapse" --health-cmd "$check" "$IMAGE" \
  serve --address 127.0.0.1 --port "$GRPC_PORT" --http-port "$HTTP_PORT" --log-format json >/dev/null
healthy=""
for _ in $(seq 1 30); do
  if podman healthcheck run "$NAME" >/dev/null 2>&1; then healthy=1; break; fi
  sleep 1
done
[ -n "$healthy" ] || fail "the HEALTHCHECK never passed"
echo "HEALTHCHECK (podman healthcheck run): healthy"
podman exec "$NAME" slapse health --server "127.0.0.1:$GRPC_PORT" --service slapse.v1.SlapseService
podman exec "$NAME" slapse health --server "127.0.0.1:$GRPC_PORT"

step "3. simulate a drive (in the image), upload it from a client container, watch to FINISHED"
slapse_run simulate --out /work/drive --seed 3 --codec mpeg2 --gop IBBBP --duration-s 8 >/dev/null
ls -l "$WORK/drive/drive.ts" | awk '{print "drive.ts:", $5, "bytes"}'
session=$(slapse_run create --server "127.0.0.1:$GRPC_PORT" --upload --intrinsics /work/drive/intrinsics.json)
echo "created $session"
slapse_run upload --server "127.0.0.1:$GRPC_PORT" "$session" /work/drive/drive.ts
slapse_run watch --server "127.0.0.1:$GRPC_PORT" "$session" >"$WORK/watch.txt" || fail "watch: the session did not finish"
grep -c " pose " "$WORK/watch.txt" | xargs echo "pose events watched:" || true
tail -1 "$WORK/watch.txt"
grep -q "state  FINISHED" "$WORK/watch.txt" || fail "the watch did not end FINISHED"
slapse_run get --server "127.0.0.1:$GRPC_PORT" "$session"

step "4. compare with offline 'slapse run' on the same file"
slapse_run export --server "127.0.0.1:$GRPC_PORT" "$session" --format tum --out /work/served_tum.txt
slapse_run run /work/drive/drive.ts --intrinsics /work/drive/intrinsics.json --out /work/offline --quiet
echo "served: $(wc -l <"$WORK/served_tum.txt") poses; offline: $(wc -l <"$WORK/offline/trajectory_tum.txt") poses"
cmp "$WORK/served_tum.txt" "$WORK/offline/trajectory_tum.txt" || fail "served and offline trajectories differ"
echo "served trajectory == offline trajectory (byte for byte)"

step "5. /metrics and the JSON logs"
metrics=$(python3 -c "import urllib.request,sys; print(urllib.request.urlopen('http://127.0.0.1:$HTTP_PORT/metrics').read().decode())")
echo "$metrics" | grep -E '^slapse_sessions\{|^slapse_session_frames_total|^slapse_rpcs_total\{code="OK",method="/slapse.v1.SlapseService/(UploadStream|WatchSession)"|^slapse_stage_seconds_count' 
echo "$metrics" | grep -q "^slapse_sessions{state=\"FINISHED\"} 1" || fail "/metrics does not count the FINISHED session"
if command -v promtool >/dev/null; then echo "$metrics" | promtool check metrics && echo "promtool check metrics: ok"; fi
podman logs "$NAME" 2>&1 | grep '"event":"state"' | head -3
podman logs "$NAME" 2>&1 | grep -q "\"session\":\"$session\"" || fail "no JSON log record names $session"

step "6. graceful stop (SIGTERM)"
podman stop -t 10 "$NAME" >/dev/null
podman logs "$NAME" 2>&1 | tail -1
echo "container-test: PASS (image $((size / 1000000)) MB)"
