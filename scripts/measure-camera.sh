#!/usr/bin/env bash
# Measures the node on the GigE camera path without a camera: Aravis's simulator
# (arv-fake-gv-camera-0.8, package aravis-tools) streams 2448x2048 BayerRG8 at 15 Hz on
# loopback and `omnirow record` runs the whole node on it for 20 s, detecting and recording.
# Prints the node's `finished` line (frames in/out, drops, recorder drops, latency), CPU per
# frame of the node, the recording's size and the peak RSS.
# Usage: scripts/measure-camera.sh [WORKDIR]   (needs: cargo build --release --features camera)
set -euo pipefail
cd "$(dirname "$0")/.."
B=target/release/omnirow
W=${1:-/tmp/omnirow-measure-camera}
rm -rf "$W" && mkdir -p "$W"
arv-fake-gv-camera-0.8 -i 127.0.0.1 -s MEASURE >/dev/null 2>&1 &
SIM=$!
trap 'kill $SIM 2>/dev/null || true' EXIT
sleep 2
cat > "$W/camera.toml" <<'TOML'
[source]
kind = "camera"
[gige]
camera = "MEASURE"
roi = { x = 0, y = 0, width = 2448, height = 2048 }
frame_rate = 15.0
realtime = false
[gige.stream]
# Loopback, as root: the packet socket receives nothing, so a UDP socket with big packets.
packet_socket = false
packet_size = 16000
socket_buffer = 8388608
[http]
enabled = false
TOML
export OMNIROW_LOG_FORMAT=json
/usr/bin/time -v $B record --out "$W/rec" --duration 20 --no-print --config "$W/camera.toml" \
  2>"$W/run.log" || true
grep '"message":"finished"' "$W/run.log" | tail -1
grep -E 'Maximum resident|User time|System time' "$W/run.log"
du -sh "$W/rec"
