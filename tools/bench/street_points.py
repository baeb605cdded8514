#!/usr/bin/env python3
"""Where the image front end's points are on imr-synth's street: road, facades, cars, elsewhere.

Reads the COLMAP text model `imr run --export-colmap DIR` writes (the final points and the images
that see them) and the sequence's ground_truth/scene.json (world_from_scene), and prints
  - the final points by surface (scene frame, z up: road = within 0.25 m of the ground z = 0 and
    inside the facades; facade = within 0.25 m of x = +-half_width above the ground; car = the
    rest up to 2 m high between the kerbs and the facades; other = anything else, i.e. off every
    surface by more than that),
  - per keyframe image (every --keyframe-every th), the mean number of points it sees on the road
    and elsewhere, and per horizontal band of the image (--bands) the mean number of points.
Plain Python (no numpy), so it runs wherever imr does.

  tools/bench/street_points.py runs/default/synthetic-street/colmap build/synthetic-street
"""
import argparse
import json
import os
import sys


def classify(xs, ys, zs, half_width):
    if abs(zs) < 0.25 and abs(xs) < half_width + 0.25:
        return "road"
    if abs(abs(xs) - half_width) < 0.25 and zs >= 0.25:
        return "facade"
    if half_width - 3.5 < abs(xs) < half_width and -0.25 < zs < 2.0:
        return "car"
    return "other"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("colmap", help="folder with images.txt and points3D.txt (imr run --export-colmap)")
    ap.add_argument("sequence", help="imr-synth sequence folder (ground_truth/scene.json, calib.txt)")
    ap.add_argument("--keyframe-every", type=int, default=5)
    ap.add_argument("--bands", type=int, default=5, help="horizontal image bands")
    ap.add_argument("--height", type=int, default=0, help="image height (default: scene.json)")
    a = ap.parse_args()

    with open(os.path.join(a.sequence, "ground_truth", "scene.json")) as f:
        scene = json.load(f)
    m = scene["world_from_scene"]
    half_width = scene["half_width"]
    height = a.height or scene["image_size"][1]

    def to_scene(x):  # x_s = R^T (x_w - t)
        d = [x[i] - m[i][3] for i in range(3)]
        return [sum(m[r][c] * d[r] for r in range(3)) for c in range(3)]

    cls = {}
    counts = {}
    with open(os.path.join(a.colmap, "points3D.txt")) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            v = line.split()
            s = to_scene([float(v[1]), float(v[2]), float(v[3])])
            c = classify(s[0], s[1], s[2], half_width)
            cls[int(v[0])] = c
            counts[c] = counts.get(c, 0) + 1
    total = sum(counts.values())
    print("final points: %d" % total)
    for c in ("road", "facade", "car", "other"):
        n = counts.get(c, 0)
        print("  %-7s %6d  %5.1f %%" % (c, n, 100.0 * n / max(total, 1)))

    keyframes = 0
    per_class = {}
    per_band = [0] * a.bands
    road_band = [0] * a.bands
    with open(os.path.join(a.colmap, "images.txt")) as f:
        lines = [l for l in f if not l.startswith("#")]
    for i in range(0, len(lines) - 1, 2):
        head, pts = lines[i].split(), lines[i + 1].split()
        if int(head[0]) % a.keyframe_every != 0:
            continue
        keyframes += 1
        for j in range(0, len(pts) - 2, 3):
            y, pid = float(pts[j + 1]), int(pts[j + 2])
            c = cls.get(pid, "other")
            per_class[c] = per_class.get(c, 0) + 1
            b = min(a.bands - 1, max(0, int(y * a.bands / height)))
            per_band[b] += 1
            if c == "road":
                road_band[b] += 1
    k = max(keyframes, 1)
    seen = sum(per_class.values())
    print("per keyframe (%d keyframes): %.1f points seen, %.1f on the road, %.1f elsewhere"
          % (keyframes, seen / k, per_class.get("road", 0) / k,
             (seen - per_class.get("road", 0)) / k))
    print("per keyframe and image band (rows), points seen (of which road):")
    for b in range(a.bands):
        print("  rows %3d-%3d  %6.1f  (%6.1f)" % (b * height // a.bands, (b + 1) * height // a.bands - 1,
                                                 per_band[b] / k, road_band[b] / k))
    return 0


if __name__ == "__main__":
    sys.exit(main())
