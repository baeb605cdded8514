#!/usr/bin/env python3
"""Per-keyframe engine time against frame index, one curve per sequence length, from
`imr-bench scaling`'s scaling.json.

usage: scaling_plot.py SCALING_JSON OUT_DIR   ->  OUT_DIR/scaling.png
Left: keyframe time (a running median over 9 keyframes; light: every keyframe) against the frame
index. Right: total engine time against frames, log-log, with the fitted exponent.
Needs python3-matplotlib.
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def running_median(v, k=9):
    h = k // 2
    out = []
    for i in range(len(v)):
        w = sorted(v[max(0, i - h):i + h + 1])
        out.append(w[len(w) // 2])
    return out


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    with open(sys.argv[1]) as f:
        data = json.load(f)
    out = sys.argv[2]
    os.makedirs(out, exist_ok=True)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [2, 1]})
    by_mode = {}
    for r in data["runs"]:
        if not r.get("ok"):
            continue
        by_mode.setdefault(r["mode"], []).append(r)
        ms = [1e3 * t for t in r["keyframe_s"]]
        line, = ax.plot(r["keyframe_frame"], running_median(ms), lw=1.2,
                        label="%s, %d frames" % (r["mode"], r["frames"]))
        ax.plot(r["keyframe_frame"], ms, lw=0.4, alpha=0.25, color=line.get_color())
    ax.set_xlabel("frame index")
    ax.set_ylabel("keyframe time (ms)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Engine time per keyframe (a keyframe every 5 frames)\nload %s-%s, %s" %
                 (data.get("load_average_start", "?"), data.get("load_average_end", "?"),
                  data.get("machine", "")), fontsize=9)
    for mode, runs in by_mode.items():
        runs.sort(key=lambda r: r["frames"])
        xs = [r["frames"] for r in runs]
        ys = [r["total_s"] for r in runs]
        b = data.get("growth_exponent", {}).get(mode, float("nan"))
        bx.loglog(xs, ys, "o-", label="%s: exponent %.2f" % (mode, b))
        if xs:
            ref = [ys[0] * x / xs[0] for x in xs]
            bx.loglog(xs, ref, ":", color="gray", lw=0.8)
    all_frames = sorted({r["frames"] for runs in by_mode.values() for r in runs})
    bx.set_xticks(all_frames)
    bx.set_xticklabels([str(f) for f in all_frames])
    bx.minorticks_off()
    bx.set_xlabel("frames")
    bx.set_ylabel("total engine time (s)")
    bx.set_title("Total time (dotted: linear)", fontsize=9)
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "scaling.png"), dpi=120)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
