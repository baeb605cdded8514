#!/usr/bin/python3
"""Test of imr_plots.py on hand-made reports: the three PNGs exist, are real pictures (decoded,
several colours), the overhead figure uses the paper's measure when a run without moves is
there, figures without data are skipped with the reason, summaries and folders are read, and
bad inputs fail. Exits 77 (CTest's skip) when matplotlib is missing."""

import json
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(HERE, "imr_plots.py")

try:
    import matplotlib  # noqa: F401
    import matplotlib.image as mpimg
    import numpy as np
except ImportError:
    print("SKIP: matplotlib is missing: install Debian's python3-matplotlib (tools/setup.sh)")
    sys.exit(77)


def report(sequence, policy, accuracy=None, total=2.0, move=0.5, moves=100, keyframes=None, rays=False):
    r = {
        "sequence": {"name": sequence, "source": sequence},
        "plugins": [] if policy is None else [{"kind": "weight_policy", "id": "org.imr.policy." + policy}],
        "engine_options": {"visibility_mode": "rays" if rays else "weights"},
        "engine": {"seconds": {"total": total, "move": move, "cast": 0.7}, "points_moved": moves,
                   "keyframes": 30},
        "mesh": {"vertices": 100, "faces": 200},
        "stage_seconds": {"engine": total, "export": 0.1},
    }
    if accuracy is not None:
        r["accuracy"] = {"truth_to_mesh": {"mean": accuracy}} if sequence != "room" else \
            {"mean_truth_to_mesh": accuracy}
    if keyframes is not None:
        r["engine"]["keyframe_seconds"] = keyframes
    return r


class ImrPlots(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="imr-plots-test-")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def write(self, name, data):
        path = os.path.join(self.dir, name)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as f:
            json.dump(data, f)
        return path

    def run_script(self, *args):
        return subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True, timeout=120)

    def check_png(self, path, min_colors=5):
        self.assertTrue(os.path.isfile(path), path)
        self.assertGreater(os.path.getsize(path), 5000, path)
        img = mpimg.imread(path)
        self.assertGreater(img.shape[0], 200)
        self.assertGreater(img.shape[1], 300)
        colors = np.unique((img[..., :3] * 255).astype(np.uint8).reshape(-1, 3), axis=0)
        self.assertGreaterEqual(len(colors), min_colors, path)
        return img

    def test_three_figures_from_reports_in_folders(self):
        kf = [0.01 + 0.001 * i for i in range(30)]
        for seq, acc in (("street", 0.12), ("room", 0.05)):
            for pol, factor in (("nearest", 1.0), ("mean", 1.3), ("weighted_mean", 1.1)):
                self.write(f"runs-{pol}/{seq}/report.json",
                           report(seq, pol, accuracy=acc * factor, move=0.4 * factor, keyframes=kf))
            self.write(f"runs-rays/{seq}/report.json",
                       report(seq, None, accuracy=acc * 0.9, total=9.0, move=3.0, rays=True, keyframes=kf))
        # A snapshot's report is not a run.
        self.write("runs-mean/street/snapshots/report.json", report("street", "mean", accuracy=99))
        out = os.path.join(self.dir, "plots")
        r = self.run_script(self.dir, "--out", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        for name in ("accuracy.png", "overhead.png", "keyframe_time.png"):
            self.check_png(os.path.join(out, name))
        self.assertIn("accuracy.png: 8 runs, 2 sequences", r.stdout)
        self.assertIn("overhead.png: 8 runs, move-phase proxy", r.stdout)
        self.assertIn("keyframe_time.png: 8 runs", r.stdout)
        self.assertEqual(sorted(f for f in os.listdir(out)), ["accuracy.png", "keyframe_time.png", "overhead.png"])

    def test_overhead_uses_a_run_without_moves_as_the_paper_did(self):
        a = self.write("a.json", report("street", "nearest", total=3.0, moves=200))
        b = self.write("b.json", report("street", "mean", total=4.0, moves=200))
        ref = self.write("ref.json", report("street", "nearest", total=1.0, moves=0))
        out = os.path.join(self.dir, "out")
        r = self.run_script(a, b, ref, "--out", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("overhead.png: 2 runs, paper's measure", r.stdout)
        self.check_png(os.path.join(out, "overhead.png"))
        # No accuracy, no per-keyframe times: skipped, saying why.
        self.assertIn("accuracy.png: skipped: no report has accuracy", r.stdout)
        self.assertIn("keyframe_time.png: skipped: no report has engine.keyframe_seconds", r.stdout)
        self.assertFalse(os.path.exists(os.path.join(out, "accuracy.png")))

    def test_batch_summary_with_embedded_and_referenced_reports(self):
        self.write("batch/street/report.json", report("street", "nearest", accuracy=0.2))
        summary = self.write("batch/summary.json", {"sequences": [
            {"name": "street", "status": "ok", "output": "street"},
            {"name": "room", "ok": True, "report": report("room", "nearest", accuracy=0.1)},
            {"name": "broken", "ok": False, "error": "x", "report": None},
        ]})
        out = os.path.join(self.dir, "out")
        r = self.run_script(summary, "--out", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("accuracy.png: 2 runs, 2 sequences", r.stdout)
        self.check_png(os.path.join(out, "accuracy.png"))

    def test_bad_inputs_fail_with_the_reason(self):
        out = os.path.join(self.dir, "out")
        r = self.run_script(os.path.join(self.dir, "missing.json"), "--out", out)
        self.assertEqual(r.returncode, 1)
        self.assertIn("missing.json: no such file or folder", r.stderr)
        bad = os.path.join(self.dir, "bad.json")
        with open(bad, "w") as f:
            f.write("{\n  \"engine\": ,\n}")
        r = self.run_script(bad, "--out", out)
        self.assertEqual(r.returncode, 1)
        self.assertIn("bad.json: malformed JSON at line 2", r.stderr)
        r = self.run_script(self.write("empty/x.json", {"nothing": 1}), "--out", out)
        self.assertEqual(r.returncode, 1)
        self.assertIn("no report among the inputs", r.stderr)
        r = self.run_script("--out", out)
        self.assertEqual(r.returncode, 2)


if __name__ == "__main__":
    unittest.main(verbosity=2)
