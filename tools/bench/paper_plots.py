#!/usr/bin/env python3
"""The two figures of Romanoni & Matteucci (Fig. 3) from `imr-bench paper`'s paper.json.

usage: paper_plots.py PAPER_JSON OUT_DIR
Writes OUT_DIR/paper_accuracy.png (a: mean distance ground truth -> mesh per sequence and
policy, medians as dots, log scale) and OUT_DIR/paper_overhead.png (b: per-point overhead
(T_mov - T_nonmov) / N_mov per policy and sequence, log scale). Needs python3-matplotlib.
"""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LABELS = {"nearest": "nearest (min. distance)", "mean": "mean", "weighted_mean": "weighted mean",
          "rays5": "Lovi et al., K = 5", "rays1": "Lovi et al., K = 1"}
COLORS = {"nearest": "#1b9e77", "mean": "#d95f02", "weighted_mean": "#7570b3",
          "rays5": "#e7298a", "rays1": "#66a61e"}


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    with open(sys.argv[1]) as f:
        data = json.load(f)
    out = sys.argv[2]
    os.makedirs(out, exist_ok=True)
    seqs = data.get("sequence_order") or list(data["sequences"].keys())
    modes = data["modes"]
    width = 0.8 / max(1, len(modes))
    sub = "load %s-%s, %s" % (data.get("load_average_start", "?"),
                              data.get("load_average_end", "?"), data.get("machine", ""))

    # (a) Accuracy per sequence and policy.
    fig, ax = plt.subplots(figsize=(max(6, 1.8 * len(seqs) + 2), 4.2))
    for k, mode in enumerate(modes):
        xs, means, medians = [], [], []
        for i, s in enumerate(seqs):
            r = data["sequences"][s].get(mode)
            if not r or not r.get("ok"):
                continue
            xs.append(i + (k - (len(modes) - 1) / 2) * width)
            means.append(r["truth_to_mesh_mean_m"])
            medians.append(r["truth_to_mesh_median_m"])
        ax.bar(xs, means, width, label=LABELS.get(mode, mode), color=COLORS.get(mode))
        ax.plot(xs, medians, "o", color="black", markersize=3)
    ax.set_yscale("log")
    ax.set_xticks(range(len(seqs)))
    ax.set_xticklabels(seqs)
    ax.set_ylabel("ground truth -> mesh distance (m, log)\nbars: mean, dots: median")
    ax.set_title("(a) Absolute errors (m)\n" + sub, fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "paper_accuracy.png"), dpi=120)
    plt.close(fig)

    # (b) Per-point overhead per policy.
    fig, ax = plt.subplots(figsize=(max(6, 1.8 * len(seqs) + 2), 4.2))
    for k, mode in enumerate(modes):
        xs, ys = [], []
        for i, s in enumerate(seqs):
            r = data["sequences"][s].get(mode)
            if not r or not r.get("ok"):
                continue
            xs.append(i + (k - (len(modes) - 1) / 2) * width)
            ys.append(max(r["per_move_overhead_s"], 1e-7))
        ax.bar(xs, ys, width, label=LABELS.get(mode, mode), color=COLORS.get(mode))
    ax.set_yscale("log")
    ax.set_xticks(range(len(seqs)))
    ax.set_xticklabels(seqs)
    ax.set_ylabel("(T_mov - T_nonmov) / N_mov (s)")
    ax.set_title("(b) Per-point overhead (s)\n" + sub, fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "paper_overhead.png"), dpi=120)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
