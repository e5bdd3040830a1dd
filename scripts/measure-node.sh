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

# The HTTP service under load (docs/http.md): the same 15 fps replay with the service on,
# alone and while a client fetches /metrics 200 times a second (a new connection each time,
# as a scraper without keep-alive), alternated twice; compare latency_p99_ms.
PORT=${OMNIROW_MEASURE_HTTP_PORT:-18347}
sed '/^\[http\]/,$d' "$W/full.toml" > "$W/http.toml"
printf '[http]\nlisten = "127.0.0.1:%s"\n' "$PORT" >> "$W/http.toml"
load() {
  python3 - "$PORT" "$1" "$2" <<'PY'
import http.client, sys, time
port, rate, seconds = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
time.sleep(2)  # the node starts
t0 = time.monotonic(); n = errors = 0; worst = 0.0
while (now := time.monotonic()) - t0 < seconds:
    due = t0 + n / rate
    if due > now:
        time.sleep(due - now)
    t = time.monotonic()
    try:
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        c.request("GET", "/metrics"); r = c.getresponse(); r.read(); c.close()
        errors += r.status != 200
    except OSError:
        errors += 1
    worst = max(worst, time.monotonic() - t); n += 1
print(f"load: {n} GET /metrics in {time.monotonic() - t0:.1f} s ({n / (time.monotonic() - t0):.0f}/s), {errors} errors, slowest {worst * 1000:.1f} ms")
PY
}
for pass in 1 2; do
  echo "== pass $pass: replay at 15 fps, 20 s, HTTP on, no client"
  $B run --replay "$F" --loop --duration 20 --no-print --config "$W/http.toml" 2>"$W/http-idle.log" || true
  fin "$W/http-idle.log"
  echo "== pass $pass: the same while GET /metrics 200 times a second for 16 s"
  load 200 16 &
  $B run --replay "$F" --loop --duration 20 --no-print --config "$W/http.toml" 2>"$W/http-load.log" || true
  wait
  fin "$W/http-load.log"
done
