#!/usr/bin/env bash
# The detector against a yardstick on the same full-resolution frame, in one run: OpenCV's
# Gaussian blur, Canny and adaptive threshold (cv2, one thread) against omnirow's combined
# detector and its Hough path (criterion, `cargo bench --bench edge`), and the ratios.
# The frame: the edge bench's, `omnirow synth --lens fisheye185 --random table1 --seed 7`
# (2448x2050 grey). OpenCV comes from the Python environment the tests make
# (scripts/ci-python-env.sh, .venv-ci).
#
#   scripts/opencv-yardstick.sh [WORKDIR]
set -euo pipefail
cd "$(dirname "$0")/.."
W=${1:-/tmp/omnirow-yardstick}
mkdir -p "$W"
scripts/ci-python-env.sh >/dev/null
cargo build --release --locked >/dev/null 2>&1
target/release/omnirow synth --lens fisheye185 --random table1 --seed 7 --out "$W/frame.png" >/dev/null 2>&1

opencv() {
  .venv-ci/bin/python - "$W/frame.png" <<'PY'
import statistics, sys, time
import cv2
cv2.setNumThreads(1)
img = cv2.imread(sys.argv[1], cv2.IMREAD_GRAYSCALE)
def once():
    blur = cv2.GaussianBlur(img, (5, 5), 1.4)
    edges = cv2.Canny(blur, 50, 150)
    kept = cv2.adaptiveThreshold(blur, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, 11, 2)
    return edges, kept
for _ in range(5):
    once()
ms = []
for _ in range(40):
    t = time.perf_counter()
    once()
    ms.append((time.perf_counter() - t) * 1e3)
print(f"{statistics.median(ms):.3f}")
PY
}

median_ms() { # criterion's output on stdin: the middle of the first `time: [a b c]`
  awk '/time:/ { v = $4; u = $5; if (u == "µs") v /= 1000; print v; exit }'
}

a=$(opencv)
combined=$(cargo bench --bench edge -- 'edge_fisheye_2448x2050/detector_combined$' 2>/dev/null | median_ms)
hough=$(cargo bench --bench edge -- 'edge_fisheye_2448x2050/detector_hough$' 2>/dev/null | median_ms)
b=$(opencv)
python3 - "$a" "$b" "$combined" "$hough" <<'PY'
import sys
a, b, combined, hough = map(float, sys.argv[1:])
cv = (a + b) / 2
print(f"OpenCV blur + Canny + adaptive threshold, one thread: {a:.2f} and {b:.2f} ms (before and after)")
print(f"combined detector: {combined:.2f} ms = {combined / cv:.2f}x OpenCV")
print(f"Hough path:        {hough:.2f} ms = {hough / cv:.2f}x OpenCV")
PY
