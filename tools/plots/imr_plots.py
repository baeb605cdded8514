#!/usr/bin/python3
"""Plots of imr's per-sequence reports (issue 6): the paper's two figures and per-keyframe time.

    tools/plots/imr_plots.py --out DIR INPUT...

INPUT: report.json files (what `imr run` writes per sequence), folders (searched for report.json,
snapshots/ skipped), or batch summaries (a JSON object with a "sequences" array: each row's
"report" object, else the report.json in its "output_directory" / "output" folder).

Writes into DIR (each PNG atomically: temporary name, then rename), each only when the reports
hold what it needs, and prints one line per figure, written or skipped and why:

  accuracy.png       mean distance ground truth -> mesh (the paper's accuracy; host/eval/README.md) per
                     sequence (groups) and policy (bars): accuracy.truth_to_mesh.mean (imr
                     evaluate), else accuracy.mean_truth_to_mesh (synthetic sources).
  overhead.png       per-move overhead per sequence and policy, in milliseconds. The paper's
                     measure is (T_mov - T_nonmov) / N_mov: a run's engine time minus that of a
                     run of the same sequence whose points did not move (engine.points_moved = 0),
                     over the run's moves; used when the inputs hold such a run. Otherwise the
                     engine's own move-phase time per move (engine.seconds.move /
                     engine.points_moved: updating the triangulation and transferring weights,
                     without the backward ray casting, which the reports time together with
                     forward casting in engine.seconds.cast); the figure says which.
  keyframe_time.png  engine time per keyframe over the sequence (engine.keyframe_seconds), one
                     panel per sequence (at most 12), one line per policy.

A run's policy: the id of its weight_policy plugin without "org.imr.policy." (plugins[].kind,
plugins[].id), "rays (Lovi et al.)" when engine_options.visibility_mode is "rays", else "none".

Needs Debian's python3-matplotlib (tools/setup.sh installs it; run with /usr/bin/python3).
Exit status: 0 done (some figures may be skipped, as printed); 1 no usable report, or an input
could not be read; 2 bad usage.
"""

import argparse
import json
import math
import os
import sys
import tempfile
import textwrap

BASELINE = "rays (Lovi et al.)"
MAX_PANELS = 12


class InputError(Exception):
    pass


def load_json(path):
    try:
        with open(path, "r", encoding="utf-8") as f:
            return json.load(f)
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})")
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: malformed JSON at line {e.lineno}, column {e.colno}")


def reports_from(path):
    """(origin, report) pairs from one INPUT."""
    if os.path.isdir(path):
        found = []
        for root, dirs, files in os.walk(path):
            dirs[:] = sorted(d for d in dirs if d != "snapshots" and not d.startswith("."))
            if "report.json" in files:
                p = os.path.join(root, "report.json")
                found.append((p, load_json(p)))
        return found
    data = load_json(path)
    if isinstance(data, dict) and isinstance(data.get("sequences"), list) and "engine" not in data:
        out = []
        base = os.path.dirname(os.path.abspath(path))
        for i, row in enumerate(data["sequences"]):
            if not isinstance(row, dict):
                raise InputError(f"{path}: sequences[{i}] is not an object")
            if isinstance(row.get("report"), dict):
                out.append((f"{path}: sequences[{i}]", row["report"]))
                continue
            folder = row.get("output_directory") or row.get("output")
            if isinstance(folder, str):
                p = os.path.join(base, folder, "report.json")
                if os.path.isfile(p):
                    out.append((p, load_json(p)))
        return out
    if isinstance(data, dict):
        return [(path, data)]
    raise InputError(f"{path}: neither a report nor a batch summary (a JSON object)")


def get(d, *keys):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def number(v):
    return v if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def policy_of(report):
    for p in report.get("plugins") or []:
        if isinstance(p, dict) and p.get("kind") == "weight_policy" and isinstance(p.get("id"), str):
            pid = p["id"]
            return pid[len("org.imr.policy."):] if pid.startswith("org.imr.policy.") else pid
    if get(report, "engine_options", "visibility_mode") == "rays":
        return BASELINE
    return "none"


class Run:
    def __init__(self, origin, report):
        self.origin = origin
        self.sequence = get(report, "sequence", "name") or os.path.basename(os.path.dirname(origin)) or "?"
        self.policy = policy_of(report)
        acc = report.get("accuracy")
        self.accuracy = number(get(acc, "truth_to_mesh", "mean"))
        if self.accuracy is None:
            self.accuracy = number(get(acc, "mean_truth_to_mesh"))
        self.engine_total = number(get(report, "engine", "seconds", "total"))
        self.move_seconds = number(get(report, "engine", "seconds", "move"))
        self.moves = number(get(report, "engine", "points_moved"))
        kf = get(report, "engine", "keyframe_seconds")
        self.keyframe_seconds = [x for x in kf if number(x) is not None] if isinstance(kf, list) else None


def label_runs(runs):
    """Unique (sequence, policy) labels: repeated pairs get " (2)", " (3)", ..."""
    seen = {}
    for r in runs:
        key = (r.sequence, r.policy)
        seen[key] = seen.get(key, 0) + 1
        r.label = r.policy if seen[key] == 1 else f"{r.policy} ({seen[key]})"


def policy_order(runs):
    order = {"none": 0, BASELINE: 1}
    labels = sorted({r.label for r in runs}, key=lambda s: (order.get(s, 2), s))
    return labels


def save(fig, path):
    """Writes the figure under a temporary name in the same folder, then renames it."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".png", dir=folder)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def grouped_bars(plt, values, sequences, labels, ylabel, title, note=None):
    """values: {(sequence, label): number}; groups = sequences, bars = labels."""
    fig, ax = plt.subplots(figsize=(max(6.0, 1.2 + 0.9 * len(sequences) * max(1, len(labels)) / 2), 4.2))
    width = 0.8 / max(1, len(labels))
    for j, label in enumerate(labels):
        xs, ys = [], []
        for i, s in enumerate(sequences):
            v = values.get((s, label))
            if v is not None:
                xs.append(i - 0.4 + width * (j + 0.5))
                ys.append(v)
        if xs:
            bars = ax.bar(xs, ys, width=width * 0.95, label=label)
            ax.bar_label(bars, fmt="%.3g", fontsize=7, padding=2)
    ax.set_xticks(range(len(sequences)))
    ax.set_xticklabels(sequences, rotation=30 if len(sequences) > 4 else 0, ha="right" if len(sequences) > 4 else "center")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.margins(y=0.15)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(title="policy", fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    if note:
        fig.text(0.01, -0.02, textwrap.fill(note, 100), fontsize=7, color="#555", ha="left", va="top")
    return fig


def plot_accuracy(plt, runs, out):
    values = {(r.sequence, r.label): r.accuracy for r in runs if r.accuracy is not None}
    if not values:
        return "skipped: no report has accuracy (accuracy.truth_to_mesh.mean or accuracy.mean_truth_to_mesh)"
    sequences = sorted({s for s, _ in values})
    labels = [l for l in policy_order(runs) if any((s, l) in values for s in sequences)]
    fig = grouped_bars(plt, values, sequences, labels,
                       "mean distance ground truth → mesh (scene units)",
                       "Accuracy per sequence and policy (lower is better)")
    save(fig, out)
    plt.close(fig)
    return f"{len(values)} runs, {len(sequences)} sequences"


def plot_overhead(plt, runs, out):
    values, paper, proxy = {}, 0, 0
    by_sequence = {}
    for r in runs:
        by_sequence.setdefault(r.sequence, []).append(r)
    for s, group in by_sequence.items():
        refs = [r for r in group if r.moves == 0 and r.engine_total is not None]
        for r in group:
            if not r.moves:
                continue
            if refs and r.engine_total is not None:
                values[(s, r.label)] = 1e3 * (r.engine_total - refs[0].engine_total) / r.moves
                paper += 1
            elif r.move_seconds is not None:
                values[(s, r.label)] = 1e3 * r.move_seconds / r.moves
                proxy += 1
    if not values:
        return "skipped: no report has moves (engine.points_moved > 0) with engine times"
    sequences = sorted({s for s, _ in values})
    labels = [l for l in policy_order(runs) if any((s, l) in values for s in sequences)]
    if proxy == 0:
        title = "Per-move overhead (T_mov − T_nonmov) / N_mov"
        note = "T_nonmov: the engine time of a run of the same sequence without moves."
    elif paper == 0:
        title = "Move-phase time per move (engine.seconds.move / points_moved)"
        note = ("No run without moves in the inputs, so not the paper's (T_mov − T_nonmov) / N_mov: "
                "the engine's move phase (triangulation update, weight transfer) per move, "
                "without backward ray casting.")
    else:
        title = "Per-move overhead"
        note = (f"{paper} runs: (T_mov − T_nonmov) / N_mov against a run without moves; {proxy} runs "
                "(no such run of their sequence): move-phase time per move, without backward casting.")
    fig = grouped_bars(plt, values, sequences, labels, "milliseconds per move", title, note)
    save(fig, out)
    plt.close(fig)
    kind = "paper's measure" if proxy == 0 else ("move-phase proxy" if paper == 0 else "mixed")
    return f"{len(values)} runs, {kind}"


def plot_keyframe_time(plt, runs, out):
    with_times = [r for r in runs if r.keyframe_seconds]
    if not with_times:
        return "skipped: no report has engine.keyframe_seconds"
    sequences = sorted({r.sequence for r in with_times})
    shown = sequences[:MAX_PANELS]
    labels = policy_order(with_times)
    colors = {l: f"C{i % 10}" for i, l in enumerate(labels)}
    fig, axes = plt.subplots(len(shown), 1, figsize=(8, 2.4 * len(shown) + 0.6), squeeze=False, sharex=False)
    for ax, s in zip(axes[:, 0], shown):
        for r in sorted((r for r in with_times if r.sequence == s), key=lambda r: labels.index(r.label)):
            ms = [1e3 * x for x in r.keyframe_seconds]
            ax.plot(range(len(ms)), ms, lw=0.9, color=colors[r.label], label=r.label)
        ax.set_title(s, fontsize=9, loc="left")
        ax.set_ylabel("ms per keyframe")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, title="policy", title_fontsize=7)
    axes[-1, 0].set_xlabel("keyframe")
    fig.suptitle("Engine time per keyframe")
    fig.tight_layout()
    save(fig, out)
    plt.close(fig)
    more = f" (first {MAX_PANELS} of {len(sequences)} sequences)" if len(sequences) > len(shown) else ""
    return f"{len(with_times)} runs{more}"


def main(argv):
    parser = argparse.ArgumentParser(
        prog="imr_plots.py", description=__doc__.split("\n\n")[0],
        epilog="Figures: accuracy.png, overhead.png, keyframe_time.png (see the script's docstring).")
    parser.add_argument("inputs", nargs="+", metavar="INPUT",
                        help="report.json files, folders holding them, or batch summary JSON files")
    parser.add_argument("--out", "-o", required=True, metavar="DIR", help="folder for the PNGs (created)")
    args = parser.parse_args(argv)

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("imr_plots.py: matplotlib is missing: install Debian's python3-matplotlib "
              "(tools/setup.sh) and run with /usr/bin/python3", file=sys.stderr)
        return 1

    runs = []
    try:
        for path in args.inputs:
            if not os.path.exists(path):
                raise InputError(f"{path}: no such file or folder")
            for origin, report in reports_from(path):
                if isinstance(report, dict) and ("engine" in report or "accuracy" in report):
                    runs.append(Run(origin, report))
    except InputError as e:
        print(f"imr_plots.py: {e}", file=sys.stderr)
        return 1
    if not runs:
        print("imr_plots.py: no report among the inputs (a report.json has \"engine\" or \"accuracy\")",
              file=sys.stderr)
        return 1
    label_runs(runs)
    os.makedirs(args.out, exist_ok=True)
    for name, fn in (("accuracy.png", plot_accuracy), ("overhead.png", plot_overhead),
                     ("keyframe_time.png", plot_keyframe_time)):
        path = os.path.join(args.out, name)
        what = fn(plt, runs, path)
        print(f"{path}: {what}" if not what.startswith("skipped") else f"{name}: {what}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
