"""imr.run (jobs), imr.evaluate, Ctrl-C."""
import json
import os
import signal
import threading
import time

import numpy as np
import pytest

import imr

from conftest import synthetic_job, write_job


def test_run_returns_the_reports_and_writes_what_imr_run_writes(tmp_path, run_imr):
    reports = imr.run(synthetic_job(tmp_path / "py", frames=20), overrides={"engine.regrow_radius": 1.5})
    assert list(reports) == ["street"]
    rep = reports["street"]
    assert rep["engine"]["keyframes"] > 0 and rep["mesh"]["faces"] > 100
    assert rep["engine_options"]["regrow_radius"] == 1.5
    assert json.load(open(tmp_path / "py" / "report.json"))["engine"] == rep["engine"]
    job = write_job(tmp_path / "job.json", synthetic_job(tmp_path / "cli", frames=20))
    r = run_imr("run", "-q", job, "--set", "engine.regrow_radius=1.5")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "py" / "mesh.ply").read_bytes() == (tmp_path / "cli" / "mesh.ply").read_bytes()
    # A job file, too; and a job's engine defaults are imr.Engine's.
    reports = imr.run(job)
    assert reports["street"]["mesh"]["faces"] > 100
    defaults = imr.Engine().options()
    for k, v in reports["street"]["engine_options"].items():
        if k in defaults and k not in ("threads", "regrow_radius"):
            assert defaults[k] == v, k


def test_invalid_job_raises_value_error_with_imr_validates_problems(tmp_path, run_imr):
    job = synthetic_job(tmp_path / "out")
    job["engine"] = {"window": -3}
    path = write_job(tmp_path / "job.json", job)
    with pytest.raises(ValueError) as e:
        imr.run(path)
    r = run_imr("run", path)
    assert r.returncode == 64
    assert str(e.value) in r.stderr, (str(e.value), r.stderr)
    with pytest.raises(ValueError, match="overrides"):
        imr.run(path, overrides={"": 1})


def test_ctrl_c_stops_a_run_cleanly(tmp_path):
    out = tmp_path / "long"
    job = synthetic_job(out, frames=20000)
    timer = threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT))
    start = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            imr.run(job)
    finally:
        timer.cancel()
    elapsed = time.monotonic() - start
    assert elapsed < 6.0, "took %.1f s to stop" % elapsed
    # Nothing half-written: no mesh, no report, no staging folder left.
    left = [p.name for p in out.iterdir()] if out.exists() else []
    assert not [n for n in left if n.startswith("mesh") or n == "report.json"], left
    assert not [n for n in left if "stag" in n or n.startswith(".")], left
    # The next call runs normally (the cancel request was cleared).
    assert imr.run(synthetic_job(tmp_path / "after", frames=10))["street"]["mesh"]["faces"] > 0


def test_evaluate_gives_imr_evaluates_figures(tmp_path, run_imr):
    imr.run(synthetic_job(tmp_path / "run", frames=30, formats=("ply",)))
    mesh = tmp_path / "run" / "mesh.ply"
    rng = np.random.default_rng(3)
    engine = imr.Engine()
    for kf in imr.read("synthetic", "street", frames=30):
        engine.add_keyframe(kf)
    vertices, faces = engine.mesh()
    truth = vertices[rng.choice(len(vertices), 500)] + rng.normal(0, 0.05, (500, 3))
    np.savetxt(tmp_path / "truth.xyz", truth, fmt="%.17g")
    py = imr.evaluate(mesh, tmp_path / "truth.xyz", tau=[0.05, 0.2], precision_samples=20000)
    r = run_imr("evaluate", mesh, "--truth", tmp_path / "truth.xyz", "--tau", "0.05,0.2",
                "--precision-samples", "20000", "--out", tmp_path / "cli.json")
    assert r.returncode == 0, r.stderr
    cli = json.load(open(tmp_path / "cli.json"))
    for k in ("completeness", "precision", "tau"):
        assert py[k] == cli[k], k
    assert py["truth_to_mesh"] == cli["truth_to_mesh"]
    assert 0.0 < py["completeness"][1] <= 1.0
    # Arrays in: the engine's mesh and the points themselves.
    arrays = imr.evaluate((vertices, faces), truth, tau=0.2, precision_samples=20000)
    assert arrays["tau"] == [0.2] and arrays["mesh"]["triangles"] == len(faces)
    assert arrays["truth_to_mesh"]["mean"] < 0.2
    with pytest.raises(ValueError, match="tau"):
        imr.evaluate(mesh, tmp_path / "truth.xyz", tau=-1)
    with pytest.raises(imr.Error, match="absent.ply"):
        imr.evaluate(tmp_path / "absent.ply", tmp_path / "truth.xyz")


def test_long_calls_release_the_gil(tmp_path):
    """Python threads run while imr.run and add_keyframe work (the GIL is released)."""
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.005)

    def busy_share(work):
        ticks.clear()
        stop.clear()
        t = threading.Thread(target=count)
        start = time.monotonic()
        t.start()
        work()
        elapsed = time.monotonic() - start
        stop.set()
        t.join()
        gaps = np.diff(ticks) if len(ticks) > 1 else np.array([elapsed])
        return elapsed, len(ticks), gaps.max()

    elapsed, n, longest = busy_share(lambda: imr.run(synthetic_job(tmp_path / "gil", frames=200)))
    assert elapsed > 0.6, "the run was too short to tell (%.2f s)" % elapsed
    assert longest < 0.3, "the other thread stalled %.2f s during imr.run" % longest

    def feed():
        engine = imr.Engine()
        for kf in imr.read("synthetic", "street", frames=200):
            engine.add_keyframe(kf)
        engine.mesh()
    elapsed, n, longest = busy_share(feed)
    assert longest < 0.3, "the other thread stalled %.2f s during add_keyframe" % longest
