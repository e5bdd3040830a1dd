#!/usr/bin/env bash
# The detector's methods on synthetic fields seen through narrow pinhole cameras looking
# straight down (where `method = "auto"` picks the pencil): renders 17 sets with
# `omnirow synth` (two cameras, 640x480 at f = 500 px and 512x512 at f = 300 px; 1 and 2 m
# high; the paper's two protocols; three appearances), labels each image's rows from its
# truth (scripts/truth-labels.py), scores every method with `omnirow eval real`, and prints
# each method's recall / precision / mean score pooled over all images (docs/detector.md).
#
#   scripts/eval-down-looking.sh [--images N] [--methods a,b,...] [--binary PATH] [OUT_DIR]
#
# Defaults: 40 images per set, the methods pencil, hough, edge, combined; the release build.
set -euo pipefail
cd "$(dirname "$0")/.."
images=40
methods="pencil,hough,edge,combined"
bin=target/release/omnirow
while [ $# -gt 0 ]; do
  case $1 in
    --images) images=$2; shift 2 ;;
    --methods) methods=$2; shift 2 ;;
    --binary) bin=$2; shift 2 ;;
    -*) echo "unknown option $1" >&2; exit 2 ;;
    *) break ;;
  esac
done
out=${1:-eval-down-out}
[ -x "$bin" ] || cargo build --release --locked
bin=$(realpath "$bin")
mkdir -p "$out/calib"
camera() { # name width height f
  cat > "$out/calib/$1.toml" <<TOML
[pinhole]
width = $2
height = $3
fx = $4
fy = $4
cx = $(python3 -c "print(($2 - 1) / 2)")
cy = $(python3 -c "print(($3 - 1) / 2)")
[mounting]
roll_deg = 0.0
pitch_deg = 0.0
yaw_deg = 0.0
TOML
}
camera f500 640 480 500.0
camera f300 512 512 300.0
sets=(
  "f500_h1_t1 f500 --random table1"
  "f500_h2_t1 f500 --random table1 --height-m 2.0"
  "f300_h1_t1 f300 --random table1"
  "f300_h2_t1 f300 --random table1 --height-m 2.0"
  "f500_h1_t2 f500 --random table2"
  "f500_h2_t2 f500 --random table2 --height-m 2.0"
  "f300_h1_t2 f300 --random table2"
  "f300_h2_t2 f300 --random table2 --height-m 2.0"
  "f500_h1_t2_colour f500 --random table2 --style colour"
  "f500_h1_t2_leafy f500 --random table2 --style leafy"
  "f300_h2_t2_leafy f300 --random table2 --style leafy --height-m 2.0"
  "f500_h1_t2_level f500 --random table2 --pitch-deg 0 --roll-deg 0"
  "f500_h2_t2_level_colour f500 --random table2 --pitch-deg 0 --roll-deg 0 --height-m 2.0 --style colour"
  "f500_h1_mid_colour f500 --random table1 --plant-distance-m 0.1 --weeds 100 --along-sd-m 0.01 --across-sd-m 0.01 --noise 0.2 --style colour"
  "f500_h2_t2_leafy f500 --random table2 --style leafy --height-m 2.0"
  "f300_h1_t2_level f300 --random table2 --pitch-deg 0 --roll-deg 0"
  "f500_h1_mid_colour_nonoise f500 --random table1 --plant-distance-m 0.1 --weeds 100 --along-sd-m 0.01 --across-sd-m 0.01 --noise 0 --style colour"
)
for spec in "${sets[@]}"; do
  read -r name cam opts <<<"$spec"
  d=$out/sets/$name
  if [ ! -d "$d/label" ]; then
    mkdir -p "$d/image" "$d/truth"
    for s in $(seq 1 "$images"); do
      # shellcheck disable=SC2086
      "$bin" synth --calib "$out/calib/$cam.toml" --seed "$s" $opts \
        --out "$d/image/$s.png" --truth "$d/truth/$s.json" >/dev/null 2>&1
    done
    python3 scripts/truth-labels.py "$out/calib/$cam.toml" "$d/truth" "$d/label"
  fi
  for m in ${methods//,/ }; do
    "$bin" eval real --images "$d/image" --labels "$d/label" --calib "$out/calib/$cam.toml" \
      --method "$m" --worst 0 --out "$out/evals/$name/$m" >/dev/null 2>&1
  done
  echo "$name: scored" >&2
done
python3 - "$out" "$methods" <<'PY'
import json, os, sys
out, methods = sys.argv[1], sys.argv[2].split(",")
print("| method | images | recall | precision | mean score |\n|---|---|---|---|---|")
for m in methods:
    labelled = inside = matched = images = 0
    scores = []
    for name in sorted(os.listdir(os.path.join(out, "evals"))):
        path = os.path.join(out, "evals", name, m, "outcomes.jsonl")
        for line in open(path):
            o = json.loads(line)
            if o["error"]:
                continue
            images += 1
            labelled += o["labelled_rows"]
            inside += o["inside_rows"]
            matched += o["matched_rows"]
            if o["score"] is not None:
                scores.append(o["score"])
    ratio = lambda a, b: a / b if b else float("nan")
    print(f"| {m} | {images} | {ratio(matched, labelled):.3f} | {ratio(matched, inside):.3f} | "
          f"{sum(scores) / max(len(scores), 1):.3f} |")
PY
