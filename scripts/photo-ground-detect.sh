#!/bin/sh
# The detector on labelled photographs' grounds seen through the ideal fisheye
# (docs/synth.md, "A ground from your own photographs").
#
# usage: scripts/photo-ground-detect.sh IMAGES LABELS [N] [BAND_SPACINGS]
#
# Renders the first N (default 20) photographs `omnirow synth --photo-survey` accepts through
# the ideal fisheye 185° at 400x480, in colour, each at yaw -15, -5, 5 or 15 degrees in turn,
# then `omnirow detect`, and prints per photograph the heading error (degrees) and how many of
# the detected rows lie within 0.5° of a true row; then the mean absolute heading error, the
# largest, and the share of detected rows on a true row.
set -eu
images=$1
labels=$2
n=${3:-20}
band=${4:-1}
bin=${OMNIROW:-target/release/omnirow}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$bin" calib ideal fisheye185 --height 400 --width 480 > "$tmp/fisheye.toml"
"$bin" synth --images "$images" --labels "$labels" --photo-survey > "$tmp/survey"
grep -v '^accepted' "$tmp/survey" | grep -n ': accepted:' | head -n "$n" | cut -d: -f1 > "$tmp/lines"
k=0
while read -r line; do
    i=$((line - 1))
    case $((k % 4)) in 0) yaw=-15 ;; 1) yaw=-5 ;; 2) yaw=5 ;; *) yaw=15 ;; esac
    "$bin" synth --images "$images" --labels "$labels" --photo-index "$i" \
        --photo-band-spacings "$band" --lens fisheye185 --image-height 400 --image-width 480 \
        --style colour --yaw-deg "$yaw" --out "$tmp/$i.png" --truth "$tmp/$i.json" 2>/dev/null
    "$bin" detect --calib "$tmp/fisheye.toml" "$tmp/$i.png" > "$tmp/$i.det"
    k=$((k + 1))
done < "$tmp/lines"
python3 - "$tmp" <<'PY'
import json, math, os, sys
d = sys.argv[1]
errs, on, total = [], 0, 0
for name in sorted((f for f in os.listdir(d) if f.endswith(".det")), key=lambda f: int(f[:-4])):
    i = name[:-4]
    det = json.load(open(os.path.join(d, name)))
    truth = json.load(open(os.path.join(d, i + ".json")))
    def angle(a, b):
        c = abs(sum(x * y for x, y in zip(a, b)))
        return math.degrees(math.acos(min(1.0, c)))
    if det.get("heading_rad") is None:
        print(f"{i}: no heading")
        errs.append(float("inf"))
        continue
    e = math.degrees(det["heading_rad"] - truth["heading_rad"])
    rows = [r["normal"] for r in det["rows"]]
    good = sum(1 for r in rows if min(angle(r, t) for t in truth["row_normals"]) < 0.5)
    errs.append(abs(e))
    on += good
    total += len(rows)
    print(f"{i}: heading error {e:+.2f} deg, {good} of {len(rows)} rows within 0.5 deg of a true row")
print(f"{len(errs)} photographs: mean |heading error| {sum(errs)/len(errs):.2f} deg, largest {max(errs):.2f} deg; {on} of {total} detected rows ({100*on/max(total,1):.0f} %) within 0.5 deg of a true row")
PY
