#!/usr/bin/env bash
# The compose stack's camera: simulates a drive, creates an RTSP push session on
# $SLAPSE, publishes the drive to it at real time with ffmpeg and watches the
# session to its end (the watch output is this container's log).
set -euo pipefail
SLAPSE=${SLAPSE:-slapse:50051}
cd /tmp
slapse simulate --out drive --seed "${SEED:-5}" --codec mpeg2 --gop IBBBP --duration-s "${DURATION_S:-20}" >/dev/null
for _ in $(seq 1 60); do slapse health --server "$SLAPSE" >/dev/null 2>&1 && break; sleep 1; done
created=$(slapse create --server "$SLAPSE" --rtsp-push cam1 --intrinsics drive/intrinsics.json)
session=$(echo "$created" | sed -n 1p)
# Line 2: the publish URL with the session's credentials (rtsp://USER:PASSWORD@0.0.0.0:8554/
# sessions/ID/cam1). The RTSP ingest port binds every interface (--rtsp-host 0.0.0.0):
# publish to it by the service's name. The log shows the URL without the credentials.
url=$(echo "$created" | sed -n 2p | sed 's#@0\.0\.0\.0:#@slapse:#')
echo "camera: $session, publishing to $(echo "$url" | sed 's#//[^@/]*@#//#')"
slapse watch --server "$SLAPSE" "$session" &
watcher=$!
for _ in $(seq 1 20); do
  ffmpeg -nostdin -loglevel error -re -i drive/drive.ts -c copy -f rtsp -rtsp_transport tcp "$url" && break
  sleep 0.5  # not reachable yet (the slapse container starting): retry
done
wait "$watcher"
slapse get --server "$SLAPSE" "$session"
