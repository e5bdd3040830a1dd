#!/usr/bin/env bash
# Measures the node at the GC2450C's full resolution (2448x2050 Bayer RGGB): replay as fast
# as possible, end-to-end latency at 15 fps, peak RSS with and without recording, and
# recording throughput at 15 fps. Usage: scripts/measure-node.sh [WORKDIR]
# Needs a release build (cargo build --release) and GNU time (/usr/bin/time).
set -euo pipefail
cd "$(dirname "$0")/.."
B=target/release/omnirow
W=${1:-/tmp/omnirow-measure}
rm -rf "$W" && mkdir -p "$W"
cat > "$W/full.toml" <<'TOML'
[source.synthetic]
width = 2448
height = 2050
fps = 15.0
[http]
enabled = false
TOML
export OMNIROW_LOG_FORMAT=json
fin() { grep '"message":"finished"' "$1" | tail -1; }
rss() { grep 'Maximum resident' "$1" | awk '{print $6/1024 " MB"}'; }

echo "== a full-resolution recording (16 synthetic frames)"
$B record --out "$W/rec" --frames 16 --no-print --config "$W/full.toml" 2>"$W/rec.log"
F=$(ls "$W"/rec/*.mcap)
ls -l "$F"

echo "== replay as fast as possible, 20 s, looping"
/usr/bin/time -v $B run --replay "$F" --rate max --loop --duration 20 --no-print \
  --config "$W/full.toml" 2>"$W/max.log" || true
fin "$W/max.log"; echo "peak RSS: $(rss "$W/max.log")"

echo "== replay at the recorded 15 fps, 20 s: end-to-end latency"
/usr/bin/time -v $B run --replay "$F" --loop --duration 20 --no-print \
  --config "$W/full.toml" 2>"$W/rt.log" || true
fin "$W/rt.log"; echo "peak RSS (no recording): $(rss "$W/rt.log")"

echo "== replay at 15 fps while recording (75 MB/s), 20 s"
/usr/bin/time -v $B record --out "$W/rec2" --replay "$F" --loop --duration 20 --no-print \
  --config "$W/full.toml" 2>"$W/recrt.log" || true
fin "$W/recrt.log"; echo "peak RSS (recording): $(rss "$W/recrt.log")"
du -sh "$W/rec2"
