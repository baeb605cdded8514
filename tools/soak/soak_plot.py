#!/usr/bin/python3
"""Resident memory over a soak, from `imr run --trace` files (what imr-soak runs).

usage: soak_plot.py OUT.png TRACE [LABEL=TRACE ...]

Left: RSS (MiB) and points kept against the keyframe, one line per trace; dots mark the keyframes
where the invariant check ran. Right: RSS against points kept, with each trace's least-squares
line (rss = a + b*points). A bare TRACE is labelled by its file name. Needs python3-matplotlib.
"""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

MIB = 1024.0 * 1024.0


def read(path):
    rows = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.strip():
                rows.append(json.loads(line))
    return rows


def fit(xs, ys):
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else 0.0
    return my - b * mx, b


def main(argv):
    if len(argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    out = argv[1]
    runs = []
    for arg in argv[2:]:
        label, _, path = arg.rpartition("=")
        runs.append((label or os.path.basename(path), read(path)))
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.4))
    px = ax.twinx()
    for label, rows in runs:
        k = [r["keyframe"] for r in rows]
        rss = [r["rss_bytes"] / MIB for r in rows]
        line, = ax.plot(k, rss, lw=1.2, label=label + ": RSS")
        checks = [(r["keyframe"], r["rss_bytes"] / MIB) for r in rows if "check_seconds" in r]
        if checks:
            ax.plot(*zip(*checks), "o", ms=3, color=line.get_color())
        px.plot(k, [r["points"] / 1e3 for r in rows], ":", lw=1, color=line.get_color(),
                label=label + ": points kept")
        pts = [r["points"] for r in rows]
        a, b = fit(pts, [r["rss_bytes"] for r in rows])
        bx.plot([p / 1e3 for p in pts], rss, lw=1.2, color=line.get_color(),
                label="%s: %.0f B/point" % (label, b))
        bx.plot([pts[0] / 1e3, pts[-1] / 1e3], [(a + b * pts[0]) / MIB, (a + b * pts[-1]) / MIB],
                "--", lw=0.8, color="gray")
    ax.set_xlabel("keyframe")
    ax.set_ylabel("resident memory (MiB); dots: invariant check")
    px.set_ylabel("points kept (thousands), dotted")
    ax.set_ylim(bottom=0)
    px.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("RSS and points kept over the run", fontsize=9)
    bx.set_xlabel("points kept (thousands)")
    bx.set_ylabel("resident memory (MiB)")
    bx.set_ylim(bottom=0)
    bx.grid(alpha=0.3)
    bx.legend(fontsize=8, loc="upper left")
    bx.set_title("RSS against points kept (dashed: least squares)", fontsize=9)
    fig.tight_layout()
    tmp = out + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, out)
    print("wrote " + out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
