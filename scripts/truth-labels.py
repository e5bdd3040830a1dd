#!/usr/bin/env python3
"""Turns `omnirow synth --truth` files into the JSON polyline labels `omnirow eval real` reads.

usage: truth-labels.py CALIB.toml TRUTH_DIR LABEL_DIR [MIN_SPAN]

CALIB is an undistorted [pinhole] calibration (fx, fy, cx, cy). omnirow's camera frame
(docs/camera-model.md) has x down the image rows, y along the columns, z out of the lens
backwards, so pixel (row r, col c) has the ray ((r - cy)/fy, (c - cx)/fx, -1), and a truth row
normal n projects to the image line c = cx + fx (n2 - n0 (r - cy)/fy) / n1. Each row is
labelled on every 4th scan line where its line lies inside the image, when it crosses at least
MIN_SPAN (default 0.25) of the scan lines; rows within a few degrees of horizontal cannot be
labelled (eval real takes one crossing per scan line) and are skipped.
"""
import json
import os
import re
import sys


def pinhole(path):
    text = open(path).read()

    def value(key):
        return float(re.search(r"^\s*%s\s*=\s*([-0-9.eE+]+)" % key, text, re.M).group(1))

    return {k: value(k) for k in ("width", "height", "fx", "fy", "cx", "cy")}


def label(normal, cal, min_span):
    n0, n1, n2 = normal
    if abs(n1) < 1e-9:
        return None
    w, h = int(cal["width"]), int(cal["height"])
    pts = []
    for r in range(h):
        c = cal["cx"] + cal["fx"] * (n2 - n0 * (r - cal["cy"]) / cal["fy"]) / n1
        if 0.0 <= c <= w - 1:
            pts.append((r, c))
    if len(pts) < max(2, min_span * h):
        return None
    sel = [p for p in pts if p[0] % 4 == 0]
    if not sel or sel[0] != pts[0]:
        sel.insert(0, pts[0])
    if sel[-1] != pts[-1]:
        sel.append(pts[-1])
    return {"xy": [[round(c, 3), r] for r, c in sel]}


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    cal = pinhole(sys.argv[1])
    truth_dir, label_dir = sys.argv[2], sys.argv[3]
    min_span = float(sys.argv[4]) if len(sys.argv) > 4 else 0.25
    os.makedirs(label_dir, exist_ok=True)
    for name in sorted(os.listdir(truth_dir)):
        if name.endswith(".json"):
            truth = json.load(open(os.path.join(truth_dir, name)))
            rows = [label(n, cal, min_span) for n in truth["row_normals"]]
            with open(os.path.join(label_dir, name), "w") as f:
                json.dump({"rows": [r for r in rows if r]}, f)


main()
