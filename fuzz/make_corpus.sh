#!/usr/bin/env bash
# Regenerates the seed corpora in fuzz/corpus/ (committed; keep them small).
#   bash fuzz/make_corpus.sh [SLAPSE_BINARY]   (default build/client/cli/slapse)
# mv_reader: short simulated drives from the real encoders (MPEG-2, MPEG-4,
# H.264; IBBBP and IPPP; MPEG-TS, plus an elementary H.264 stream), each also
# truncated and with corrupted bytes. The other harnesses' seeds are small
# hand-written texts (and serialized protos via protoc --encode).
set -euo pipefail
cd "$(dirname "$0")/.."
SLAPSE=${1:-build/client/cli/slapse}
OUT=fuzz/corpus
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
rm -rf "$OUT"
mkdir -p "$OUT"/{mv_reader,sdp_url,intrinsics,upload_queue,session_proto}

# Keeps the first N bytes of $1 in $2.
truncate_to() { head -c "$3" "$1" > "$2"; }
# Copies $1 to $2 with 16 bytes overwritten at every step of $3 bytes (deterministic).
corrupt() {
  python3 - "$1" "$2" "$3" <<'PY'
import sys
data = bytearray(open(sys.argv[1], 'rb').read())
step = int(sys.argv[3])
for pos in range(step // 2, len(data) - 16, step):
    data[pos:pos + 16] = bytes((pos * 7 + i * 13) & 0xFF for i in range(16))
open(sys.argv[2], 'wb').write(data)
PY
}

# --- mv_reader: real encoder output, 160x128, 0.4 s ---
for codec in mpeg2 mpeg4 h264; do
  for gop in IBBBP IPPP; do
    d="$TMP/$codec-$gop"
    "$SLAPSE" simulate --out "$d" --seed 1 --codec "$codec" --gop "$gop" --gop-size 6 \
      --duration-s 0.4 --width 160 --height 128 --no-trees > /dev/null
    v="$OUT/mv_reader/$codec-$gop.ts"
    cp "$d/drive.ts" "$v"
    size=$(stat -c %s "$v")
    truncate_to "$v" "$OUT/mv_reader/$codec-$gop-truncated.ts" $((size / 3 / 188 * 188 + 100))
    corrupt "$v" "$OUT/mv_reader/$codec-$gop-corrupt.ts" 4096
  done
done
# An elementary H.264 stream (Annex B), as an upload may send it.
ffmpeg -v error -i "$OUT/mv_reader/h264-IBBBP.ts" -c copy -bsf:v h264_mp4toannexb -f h264 \
  "$OUT/mv_reader/h264-IBBBP.h264"
ffmpeg -v error -i "$OUT/mv_reader/mpeg2-IBBBP.ts" -c copy -f mpeg2video "$OUT/mv_reader/mpeg2-IBBBP.m2v"

# --- sdp_url: first byte even = SDP, odd = URL parts (see fuzz_sdp_url.cc) ---
printf '\x00v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=cam\r\nc=IN IP4 127.0.0.1\r\nt=0 0\r\nm=video 5004 RTP/AVP 96\r\na=rtpmap:96 H264/90000\r\n' \
  > "$OUT/sdp_url/sdp_h264"
printf '\x00v=0\nc=IN IP4 0.0.0.0\nm=video 0 RTP/AVP 32\n' > "$OUT/sdp_url/sdp_port0"
printf '\x01rtsp\nadmin\ncam.local:554/stream1?x=1' > "$OUT/sdp_url/url_host"
printf '\x01rtsps\nuser\n[::1]:8554/a' > "$OUT/sdp_url/url_ipv6"
printf '\x01RTSP\na@b\n10.0.0.7' > "$OUT/sdp_url/url_at_user"

# --- intrinsics: first byte even = spec (and stream size), odd = JSON text ---
printf '\x02500,500,319.5,239.5' > "$OUT/intrinsics/spec_numbers"
printf '\x04hfov=70' > "$OUT/intrinsics/spec_hfov"
printf '\x01{"fx_px": 500, "fy_px": 500, "cx_px": 319.5, "cy_px": 239.5, "width_px": 640, "height_px": 480}' \
  > "$OUT/intrinsics/json_intrinsics"
printf '\x01{"planes": [{"id": 0, "kind": "road", "normal_world": [0, 1, 0], "distance_m": 1.5}], "n": 3}' \
  > "$OUT/intrinsics/json_planes"

# --- upload_queue: capacity, limit, then (op, arg) pairs ---
printf '\x10\x00\x00\x20\x03\x08\x00\x40\x03\x40\x01\x00\x03\x10\x03\x10' > "$OUT/upload_queue/write_read_finish"
printf '\x02\x04\x00\xff\x00\x30\x03\x05\x00\x30\x02\x01\x03\x01' > "$OUT/upload_queue/limit_close"

# --- session_proto: serialized v1::Session messages ---
encode() { protoc -I proto --encode=slapse.v1.Session proto/slapse/v1/slapse.proto > "$OUT/session_proto/$1"; }
K='intrinsics { fx_px: 500 fy_px: 500 cx_px: 319.5 cy_px: 239.5 width_px: 640 height_px: 480 }'
echo "upload {} $K pipeline_options { eps_h_px: 2 scale_source: 1 speed_mps: 10 }" | encode upload
echo "rtsp_pull { url: \"rtsp://u:p@cam:554/1\" reconnect { max_attempts: 3 initial_interval_ms: 500 backoff_multiplier: 2 max_interval_ms: 4000 } start_timeout_ms: 1000 } $K" | encode rtsp_pull
echo "rtsp_push { path: \"cams/front\" receive_timeout_ms: 2000 } $K" | encode rtsp_push
echo "rtp_sdp { sdp: \"v=0\nc=IN IP4 127.0.0.1\nm=video 5004 RTP/AVP 96\n\" } $K" | encode rtp_sdp
echo "upload {} intrinsics { fx_px: -1 }" | encode bad_intrinsics

du -sh "$OUT"
