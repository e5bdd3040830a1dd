#!/usr/bin/env python3
"""Scores the synthetic drive's estimates (`omnirow run --print`, JSON lines on stdin) against
the ground truth each carries.

usage: omnirow run --config C --frames N --print | scripts/score-guidance.py

Prints one line: frames; frames with a guidance offset; frames whose followed row is not the
inter-row path the camera is in (row jumps); the offset error |guidance.lateral_offset_m -
truth offset from the path's centre line| mean and p99; the guidance heading error
|guidance.heading_rad - truth.heading_rad| p99; and the vanishing point's heading error
(heading_rad against truth, sign free) median and p99. Percentiles are nearest rank.
"""
import json
import math
import sys


def quantile(v, q):
    v = sorted(v)
    return v[min(len(v) - 1, round((len(v) - 1) * q))] if v else float("nan")


def main():
    off, head, vp = [], [], []
    frames = jumps = 0
    for line in sys.stdin:
        e = json.loads(line)
        frames += 1
        t = e["truth"]
        g = e.get("guidance") or {}
        if e["heading_rad"] is not None:
            d = (e["heading_rad"] - t["heading_rad"]) % math.pi
            vp.append(math.degrees(min(d, math.pi - d)))
        if g.get("lateral_offset_m") is None:
            continue
        spacing = t["row_spacing_m"]
        path = math.floor(t["camera_lateral_m"] / spacing)
        off.append(abs(g["lateral_offset_m"] - (t["camera_lateral_m"] - (path + 0.5) * spacing)))
        head.append(abs(math.degrees(g["heading_rad"] - t["heading_rad"])))
        if g.get("row_index") is not None and g["row_index"] != path:
            jumps += 1
    mean = sum(off) / len(off) if off else float("nan")
    print(
        f"frames {frames}, with an offset {len(off)}, row jumps {jumps}; "
        f"offset error mean {1000 * mean:.1f} mm, p99 {1000 * quantile(off, 0.99):.1f} mm; "
        f"guidance heading error p99 {quantile(head, 0.99):.2f} deg; "
        f"vanishing point heading error median {quantile(vp, 0.5):.2f}, "
        f"p99 {quantile(vp, 0.99):.2f} deg ({len(vp)} frames)"
    )


if __name__ == "__main__":
    main()
