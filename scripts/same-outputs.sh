#!/usr/bin/env bash
# Runs two omnirow binaries on the same inputs and compares their outputs outcome by
# outcome: all CRDLD images at both focal-length guesses (`omnirow eval real`, when
# ../shared/real-fields/crdld exists: the strips method), `omnirow eval --quick` (Tables I
# and II: the Hough, edge and combined methods), `omnirow eval guidance --seconds 10` (every
# frame) and `omnirow detect` on 24 synthetic images through a narrow camera looking down
# (the pencil method). Timings are left out of the comparison. A change that must not change what the detector finds (a restructuring, a
# speed-up) passes when this prints "same outputs" and exits 0.
#
#   scripts/same-outputs.sh BEFORE_BINARY AFTER_BINARY [OUT_DIR]
#
# e.g. build the old commit into another folder, then
#   scripts/same-outputs.sh ../old/target/release/omnirow target/release/omnirow
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { echo "usage: $0 BEFORE_BINARY AFTER_BINARY [OUT_DIR]" >&2; exit 2; }
before=$(realpath "$1")
after=$(realpath "$2")
out=${3:-$(mktemp -d)}
crdld=../shared/real-fields/crdld

# A narrow perspective camera looking straight down, and its images (rendered once).
down=$out/down
mkdir -p "$down/image"
cat > "$down/calib.toml" <<'TOML'
[pinhole]
width = 640
height = 480
fx = 500.0
fy = 500.0
cx = 319.5
cy = 239.5
[mounting]
roll_deg = 0.0
pitch_deg = 0.0
yaw_deg = 0.0
TOML
for s in $(seq 1 24); do
  random=table1
  [ $((s % 2)) = 0 ] && random=table2
  "$before" synth --calib "$down/calib.toml" --seed "$s" --random $random \
    --out "$down/image/$s.png" >/dev/null 2>&1
done

run() { # binary, folder
  local bin=$1 dir=$2
  mkdir -p "$dir"
  "$bin" detect --calib "$down/calib.toml" "$down"/image/*.png > "$dir/down.jsonl"
  if [ -d "$crdld/image" ]; then
    for f in 300 900; do
      "$bin" eval real --images "$crdld/image" --labels "$crdld/label" \
        --calib "config/calib/pinhole_512_f$f.toml" --out "$dir/crdld$f" --worst 0 >/dev/null
    done
  fi
  "$bin" eval --quick --out "$dir/quick" >/dev/null 2>&1
  "$bin" eval guidance --seconds 10 --out "$dir/guidance" >/dev/null 2>&1
}

[ -d "$crdld/image" ] || echo "$crdld is absent: CRDLD not compared" >&2
echo "before: $before -> $out/before" >&2
run "$before" "$out/before"
echo "after: $after -> $out/after" >&2
run "$after" "$out/after"

python3 - "$out/before" "$out/after" <<'PY'
import json, os, sys

before, after = sys.argv[1], sys.argv[2]
TIMING = {"detect_ms", "elapsed_ms"}

def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if k not in TIMING}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v

def lines(path):
    with open(path) as f:
        return [strip(json.loads(l)) for l in f if l.strip()]

files = []
for root, _, names in os.walk(before):
    for n in names:
        if n.endswith(".jsonl"):
            files.append(os.path.relpath(os.path.join(root, n), before))
differ = 0
for rel in sorted(files):
    a = lines(os.path.join(before, rel))
    b = lines(os.path.join(after, rel)) if os.path.exists(os.path.join(after, rel)) else []
    bad = [i for i in range(max(len(a), len(b))) if i >= len(a) or i >= len(b) or a[i] != b[i]]
    print(f"{rel}: {len(a)} outcomes before, {len(b)} after, {len(bad)} differ")
    for i in bad[:5]:
        print(f"  outcome {i}:\n    before {json.dumps(a[i]) if i < len(a) else '-'}\n"
              f"    after  {json.dumps(b[i]) if i < len(b) else '-'}")
    differ += len(bad)
print("same outputs" if differ == 0 else f"{differ} outcomes differ")
sys.exit(1 if differ else 0)
PY
