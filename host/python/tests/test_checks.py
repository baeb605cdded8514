"""The module checks what the CLI checks, in its words (issue 44): cameras, coordinates, ids,
options at construction, imr.run's output folder, threads, dict jobs, evaluate's arrays."""
import json
import re
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import imr

from conftest import synthetic_job, write_job

I3 = np.eye(3)


def slam_scene(rotation=None, focal=800, x=(2, 2.5, 7), removed=None):
    """A two-view SLAM JSON 0.3 stream (the readers_test scene), with one field made bad."""
    r1 = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]] if rotation is None else np.asarray(rotation).tolist()
    j = {"slam_data_version": "0.3", "root_path": "",
         "intrinsics": [{"intrinsicId": 0, "value": {"polymorphic_id": 0, "polymorphic_name": "pinhole",
                         "ptr_wrapper": {"data": {"width": 640, "height": 480, "focal_length": focal,
                                                  "principal_point": [320, 240]}}}}],
         "views": [
             {"viewId": 1, "local_path": "/", "filename": "a.png", "width": 640, "height": 480,
              "id_intrinsic": 0, "extrinsic": {"rotation": r1, "center": [1, 2, 3]},
              "observations": [{"pointId": 7, "X": [2, 2.5, 7.5], "x": [420, 40]}]},
             {"viewId": 2, "local_path": "/", "filename": "b.png", "width": 640, "height": 480,
              "id_intrinsic": 0, "extrinsic": {"rotation": I3.tolist(), "center": [3, 2, 3]},
              "observations": [{"pointId": 7, "X": list(x), "x": [120, 340]}]}]}
    if removed is not None:
        j["imr_stream"] = {"keyframes": [{"keyframe": 0, "frame": 0},
                                         {"keyframe": 1, "frame": 1, "removed_points": removed}]}
        j["views"][0]["keyframe"] = 0
        j["views"][1]["keyframe"] = 1
    return j


def reader_error(tmp_path, scene):
    """What the CLI's SLAM JSON reader (imr run's, here through the module) says of `scene`."""
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(scene))
    with pytest.raises(imr.Error) as e:
        list(imr.read_slam_json(path, min_views=1))
    return str(e.value)


def engine_error(camera=None, **keyframe):
    """The ValueError of one keyframe fed to a fresh engine (its message after 'keyframe ...: ')."""
    engine = imr.Engine()
    with pytest.raises(ValueError) as e:
        engine.add_keyframe(camera if camera is not None else imr.Camera(0, center=(0, 0, 0)), **keyframe)
    return str(e.value)


@pytest.mark.parametrize("name, rotation", [
    ("all ones", np.ones((3, 3))), ("zeros", np.zeros((3, 3))),
    ("reflection", np.diag([1.0, 1.0, -1.0])), ("2 I", 2 * I3)])
def test_rotations_that_are_not_rotations_are_refused_in_the_readers_words(tmp_path, name, rotation):
    with pytest.raises(ValueError) as e:
        imr.Camera(3, center=(0, 0, 0), rotation=rotation)
    message = str(e.value)
    assert message.startswith("camera 3: the rotation is not a rotation: "), message
    words = message[len("camera 3: "):]
    assert words in reader_error(tmp_path, slam_scene(rotation=rotation)), (words, name)


def test_a_rotation_1e_6_off_is_accepted_and_made_orthonormal_as_the_readers_do():
    r = I3.copy()
    r[0, 0] += 1.4e-6
    cam = imr.Camera(0, center=(0, 0, 0), rotation=r)
    assert np.allclose(cam.rotation @ cam.rotation.T, I3, atol=1e-13)
    imr.Engine().add_keyframe(cam, new_ids=[1], new_positions=[[0, 0, 5]])


@pytest.mark.parametrize("intrinsics", [
    (float("nan"), 500, 320, 240), (0, 500, 320, 240), (-500, -500, 320, 240), (500, 0, 320, 240)])
def test_intrinsics_nan_zero_or_negative_are_refused_as_the_readers_refuse_them(tmp_path, intrinsics):
    with pytest.raises(ValueError) as e:
        imr.Camera(0, center=(0, 0, 0), intrinsics=intrinsics)
    assert "camera 0: intrinsics: expected focal lengths fx, fy finite and > 0 (pixels)" in str(e.value)
    common = "expected focal lengths fx, fy finite and > 0 (pixels), got fx 0, fy 0"
    assert common in reader_error(tmp_path, slam_scene(focal=0))
    # All zeros: unknown (the default), as before.
    imr.Camera(0, center=(0, 0, 0), intrinsics=(0, 0, 0, 0))
    with pytest.raises(ValueError, match="principal point"):
        imr.Camera(0, center=(0, 0, 0), intrinsics=(500, 500, float("inf"), 240))


@pytest.mark.parametrize("far", [1e13, 1e300, -1e13])
def test_coordinates_beyond_the_readers_bound_are_refused_not_dropped(tmp_path, far):
    bound = "expected a coordinate within +-1e12 (scene units), got %g" % far
    assert bound in reader_error(tmp_path, slam_scene(x=(2, far, 7)))
    m = engine_error(new_ids=[1, 2], new_positions=[[0, 0, 5], [0, far, 5]])
    assert m == "keyframe 0 (frame 0): new_points: point 2: y: " + bound, m
    with pytest.raises(ValueError, match=re.escape("camera 4: center x: " + bound)):
        imr.Camera(4, center=(far, 0, 0))
    engine = imr.Engine()
    engine.add_keyframe(imr.Camera(0, center=(0, 0, 0)), new_ids=[1], new_positions=[[0, 0, 5]])
    with pytest.raises(ValueError) as e:
        engine.add_keyframe(moved_ids=[1], moved_positions=[[0, 0, far]])
    assert str(e.value) == "keyframe 1 (frame 1): moved_points: point 1: z: " + bound
    # The engine's state is the one before the refused keyframe: it goes on.
    engine.add_keyframe(imr.Camera(1, center=(0.5, 0, 0)), new_ids=[2], new_positions=[[1, 0, 5]])
    assert engine.keyframes == 2


def test_ids_are_known_and_removed_once_in_the_slam_json_readers_words(tmp_path):
    engine = imr.Engine()
    cam = imr.Camera(0, center=(0, 0, 0))
    engine.add_keyframe(cam, new_ids=[1, 2, 3], new_positions=[[0, 0, 5], [1, 0, 5], [0, 1, 5]])
    engine.add_keyframe(removed_ids=[1])
    with pytest.raises(ValueError) as e:
        engine.add_keyframe(removed_ids=[1])  # twice
    assert str(e.value) == "keyframe 2 (frame 2): removed_points: point 1 is not in the stream at keyframe 2"
    # The reader's words for a point removed that is not in the stream.
    assert "removed_points: point 7 is not in the stream at keyframe 0" in reader_error(
        tmp_path, dict(slam_scene(), imr_stream={"keyframes": [
            {"keyframe": 0, "frame": 0, "removed_points": [7]}, {"keyframe": 1, "frame": 1}]}))
    with pytest.raises(ValueError, match="removed_points: point 99 is not in the stream at keyframe 2"):
        engine.add_keyframe(removed_ids=[99])  # unknown
    with pytest.raises(ValueError, match="moved_points: point 1 is observed after it was removed"):
        engine.add_keyframe(moved_ids=[1], moved_positions=[[0, 0, 6]])
    with pytest.raises(ValueError, match="moved_points: point 98 is not in the stream at keyframe 2"):
        engine.add_keyframe(moved_ids=[98], moved_positions=[[0, 0, 6]])
    with pytest.raises(ValueError, match="point 1 uses the id of a point removed at keyframe 1"):
        engine.add_keyframe(cam, new_ids=[1], new_positions=[[0, 0, 7]])
    # None of the refused keyframes counted; the good ones go on.
    engine.add_keyframe(moved_ids=[2], moved_positions=[[1, 0, 5.5]], removed_ids=[3])
    assert engine.keyframes == 3


def test_engine_options_are_checked_at_construction():
    with pytest.raises(ValueError) as e:
        imr.Engine(max_ray_length=1e12)
    assert "Steiner grid" in str(e.value) and "max_ray_length" in str(e.value), str(e.value)
    imr.Engine(max_ray_length=1e12, scale="auto")  # left to the first keyframes' scale
    with pytest.raises(ValueError, match="engine.threads"):
        imr.Engine(threads=-1)


def user_folder(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "report.json").write_text('{"my": "own report"}\n')
    (out / "mesh.ply").write_bytes(b"ply\nformat ascii 1.0\ncomment the user's own\nend_header\n")
    return out, {p.name: p.read_bytes() for p in out.iterdir()}


def test_run_refuses_a_folder_with_the_users_report_as_imr_run_does(tmp_path, run_imr):
    out, before = user_folder(tmp_path)
    job = write_job(tmp_path / "job.json", synthetic_job(out, frames=10))
    with pytest.raises(imr.SequenceError) as e:
        imr.run(job)
    message = str(e.value)
    assert e.value.sequence == "street"
    assert "report.json: not a report of this job's sequence 'street'" in message, message
    assert "imr would overwrite it" in message
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    r = run_imr("run", job)
    assert r.returncode == 1 and message in r.stdout + r.stderr, (message, r.stdout, r.stderr)
    for name, data in before.items():  # (imr run may add its batch page beside them)
        assert (out / name).read_bytes() == data, name
    # A dict job too.
    with pytest.raises(imr.SequenceError, match="not a report of this job's sequence"):
        imr.run(synthetic_job(out, frames=10))
    for name, data in before.items():
        assert (out / name).read_bytes() == data, name


def test_threads_outside_the_range_are_refused_in_the_module_and_the_cli(tmp_path, run_imr):
    job = write_job(tmp_path / "job.json", synthetic_job(tmp_path / "out", frames=5))
    for n in (-1, 1025):
        with pytest.raises(ValueError, match="expected a number of threads in 1..1024"):
            imr.run(job, threads=n)
        r = run_imr("run", job, "--threads", n)
        assert r.returncode != 0 and "expected a number of threads in 1..1024" in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


def test_a_dict_jobs_errors_name_the_dict_not_a_job_json(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    job = synthetic_job(tmp_path / "out")
    job["engine"] = {"window": -3}
    with pytest.raises(ValueError) as e:
        imr.run(job)
    assert str(e.value).startswith("the job (a dict): 1 problem:"), str(e.value)
    assert "job.json" not in str(e.value)
    with pytest.raises(ValueError) as e:
        imr.run(synthetic_job(tmp_path / "out"), threads=-1)
    assert "job.json" not in str(e.value)
    assert not (tmp_path / "job.json").exists()


def test_evaluate_on_arrays_writes_nothing_and_names_no_temporary(tmp_path, monkeypatch):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    faces = np.array([[0, 1, 2]])
    truth = np.array([[0.2, 0.2, 0.01], [0.5, 0.1, 0.0]])
    report = imr.evaluate((vertices, faces), truth, tau=0.05, precision_samples=1000, crop=False)
    assert report["mesh"]["path"] == "<arrays>" and report["truth"]["path"] == "<array>"
    assert report["completeness"] == [1.0]
    with pytest.raises(ValueError) as e:
        imr.evaluate((vertices, np.array([[0, 1, 3]])), truth)
    assert str(e.value) == "mesh: faces[0]: vertex index 3 is out of range (3 vertices)"
    with pytest.raises(ValueError) as e:  # a mesh of no area: the evaluation's own error
        imr.evaluate((np.zeros((3, 3)), faces), truth)
    assert str(tmp) not in str(e.value) and "imr-evaluate" not in str(e.value), str(e.value)
    with pytest.raises(ValueError, match=r"truth\[1\]: expected finite numbers"):
        imr.evaluate((vertices, faces), np.array([[0, 0, 0], [np.nan, 0, 0]]))
    assert os.listdir(tmp) == []


def test_evaluate_killed_by_sigterm_leaves_no_copy_of_the_users_data(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    script = (
        "import sys, numpy as np, imr\n"
        "rng = np.random.default_rng(1)\n"
        "v = rng.random((100000, 3)); f = rng.integers(0, 100000, (200000, 3))\n"
        "t = rng.random((500000, 3))\n"
        "print('ready', flush=True)\n"
        "imr.evaluate((v, f), t, tau=0.1, precision_samples=2000000, crop=False)\n")
    env = dict(os.environ, TMPDIR=str(tmp))
    child = subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    assert child.poll() is None, "the evaluation ended before the signal"
    child.send_signal(signal.SIGTERM)
    child.wait(timeout=30)
    assert os.listdir(tmp) == [], os.listdir(tmp)
