#!/usr/bin/env bash
# Measures the node at the GC2450C's full resolution (2448x2050 Bayer RGGB): replay as fast
# as possible, end-to-end latency at 15 fps, peak RSS with and without recording, and
# recording throughput at 15 fps, and the pipeline's latency with the HTTP service under load.
# Usage: scripts/measure-node.sh [WORKDIR]; OMNIROW_MEASURE_ONLY=http runs only the HTTP
# section (after the recording it replays), OMNIROW_MEASURE_HTTP_PAIRS=N its pairs (3),
# OMNIROW_MEASURE_HTTP_CLIENT_NICE=N the load client's niceness (0; 19 stands in for a scraper
# on another machine: the client then takes only the CPU time the node leaves),
# OMNIROW_MEASURE_HTTP_SECONDS=S how long each load lasts (10; a p99 over 10 s is ~150 frames).
# Needs a release build (cargo build --release), GNU time (/usr/bin/time) and python3.
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

if [ "${OMNIROW_MEASURE_ONLY:-}" != http ]; then
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
fi

# The HTTP service under load (docs/http.md): pairs of 12 s replays at 15 fps with the service
# on, one without a client and one while a client fetches /metrics 200 times a second for 10 s
# (both lengths grow with OMNIROW_MEASURE_HTTP_SECONDS)
# (a new connection each time, as a scraper without keep-alive; from when /healthz first
# answers), in turn (A B A B ...) so that the machine's drift hits both alike. Per run, the p99
# of the end-to-end latency of the frames received after the first second; per pair, the
# difference and the ratio loaded / idle; at the end their medians.
PORT=${OMNIROW_MEASURE_HTTP_PORT:-18347}
PAIRS=${OMNIROW_MEASURE_HTTP_PAIRS:-3}
LOAD_S=${OMNIROW_MEASURE_HTTP_SECONDS:-10}
RUN_S=$((LOAD_S + 2))
sed '/^\[http\]/,$d' "$W/full.toml" > "$W/http.toml"
printf '[http]\nlisten = "127.0.0.1:%s"\n' "$PORT" >> "$W/http.toml"
load() {
  python3 - "$PORT" "$1" "$2" <<'PY'
import http.client, sys, time
port, rate, seconds = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
def get(path):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    try:
        c.request("GET", path); r = c.getresponse(); r.read(); return r.status
    finally:
        c.close()
# The node starts: begin once it serves (its first frames flow about then).
started = time.monotonic()
while time.monotonic() - started < 30:
    try:
        if get("/healthz") == 200:
            break
    except OSError:
        pass
    time.sleep(0.05)
t0 = time.monotonic(); n = errors = 0; worst = 0.0; kinds = {}
while (now := time.monotonic()) - t0 < seconds:
    due = t0 + n / rate
    if due > now:
        time.sleep(due - now)
    t = time.monotonic()
    try:
        status = get("/metrics")
        if status != 200:
            errors += 1; kinds[status] = kinds.get(status, 0) + 1
    except OSError as e:
        errors += 1; kinds[type(e).__name__] = kinds.get(type(e).__name__, 0) + 1
    worst = max(worst, time.monotonic() - t); n += 1
print(f"load: {n} GET /metrics in {time.monotonic() - t0:.1f} s ({n / (time.monotonic() - t0):.0f}/s), {errors} errors {kinds or ''}, slowest {worst * 1000:.1f} ms")
PY
}
# The p99 latency (ms) and frame count of the estimates in $1 received 1 s or more after the
# first (the node serves HTTP from about its first frame, and the load begins then).
window_p99() {
  python3 - "$1" <<'PY'
import json, sys
est = [json.loads(l) for l in open(sys.argv[1]) if l.startswith("{")]
est = [e for e in est if e.get("status") != "camera_lost"]
t0 = est[0]["receive_ns"] if est else 0
lat = sorted(e["latency_ms"] for e in est if e["receive_ns"] >= t0 + 1e9)
q = lambda f: lat[min(len(lat) - 1, int(f * len(lat)))] if lat else float("nan")
print(f"{q(0.99):.2f} {len(lat)} {q(0.5):.2f}")
PY
}
: > "$W/http-pairs.txt"
for pair in $(seq "$PAIRS"); do
  $B run --replay "$F" --loop --duration "$RUN_S" --print --config "$W/http.toml" \
    >"$W/http-idle-$pair.jsonl" 2>"$W/http-idle-$pair.log" || true
  # The client runs on the node's cores at the same priority as the pipeline (a scraper is
  # usually another machine): its own CPU time counts against the service here.
  (renice -n "${OMNIROW_MEASURE_HTTP_CLIENT_NICE:-0}" -p "$BASHPID" >/dev/null; load 200 "$LOAD_S") \
    >"$W/http-load-$pair.txt" &
  $B run --replay "$F" --loop --duration "$RUN_S" --print --config "$W/http.toml" \
    >"$W/http-load-$pair.jsonl" 2>"$W/http-load-$pair.log" || true
  wait
  read -r idle n_idle idle50 < <(window_p99 "$W/http-idle-$pair.jsonl")
  read -r loaded n_loaded loaded50 < <(window_p99 "$W/http-load-$pair.jsonl")
  echo "$idle $loaded" >> "$W/http-pairs.txt"
  echo "== pair $pair: latency p99 (p50) idle $idle ($idle50) ms, $n_idle frames; under /metrics load $loaded ($loaded50) ms, $n_loaded frames; $(cat "$W/http-load-$pair.txt")"
done
python3 - "$W/http-pairs.txt" <<'PY'
import statistics, sys
pairs = [tuple(map(float, l.split())) for l in open(sys.argv[1]) if l.strip()]
d = statistics.median(b - a for a, b in pairs)
r = statistics.median(b / a for a, b in pairs)
print(f"== HTTP load over {len(pairs)} pairs: median difference loaded - idle {d:+.2f} ms, median ratio loaded / idle {r:.3f}")
PY
