"""The readers fed to imr.Engine give what `imr run` / `imr mesh` give on the same input."""
import json
import os
import shlex
import subprocess
import sys

import numpy as np
import pytest

import imr

from conftest import read_binary_ply, synthetic_job, write_job


def street_stream(shared_dir):
    """The independent street stream (../shared/data/street-stream: a SLAM run's views with
    moving points), whole: about 4 s in each of imr run and the module."""
    path = os.path.join(shared_dir, "data", "street-stream", "slam.json") if shared_dir else ""
    if not path or not os.path.exists(path):
        pytest.skip("the street stream is absent (IMR_SHARED_DIR/data/street-stream/slam.json)")
    return path


def test_street_stream_fed_from_python_is_imr_runs_mesh(shared_dir, tmp_path, run_imr):
    stream = street_stream(shared_dir)
    # A job's defaults (engine.scale auto for slam_json, as imr run) but forgetting: imr run
    # writes a forgetting run's mesh in the order its parts became final (the next test).
    engine = imr.Engine(forget=False)
    for kf in imr.read_slam_json(stream):
        engine.add_keyframe(kf)
    engine.write(tmp_path / "py" / "mesh.ply")

    job = write_job(tmp_path / "job.json", {
        "sequences": [stream], "input": {"format": "slam_json"}, "engine": {"forget": False},
        "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
        "output": {"directory": str(tmp_path / "cli"), "formats": ["ply"]}})
    r = run_imr("run", "-q", job)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.load(open(tmp_path / "cli" / "report.json"))
    assert report["engine"]["points_moved"] > 1000  # the stream's points move

    cli = (tmp_path / "cli" / "mesh.ply").read_bytes()
    assert len(cli) > 100000
    assert (tmp_path / "py" / "mesh.ply").read_bytes() == cli, "other PLY bytes than imr run's"
    stats = engine.stats()
    for k in ("keyframes", "rays_cast", "rays_cast_backward", "points_inserted", "points_moved",
              "moves_skipped", "cells", "cells_in_o", "steiner_points"):
        assert stats[k] == report["engine"][k], k
    assert stats["scale"]["mode"] == "auto"
    # The arrays are the mesh the PLY holds: as many vertices and faces, the same positions
    # (the PLY's are float32).
    vertices, faces = engine.mesh()
    assert len(faces) == report["mesh"]["faces"] and len(vertices) == report["mesh"]["vertices"]
    ply_vertices, ply_faces = read_binary_ply(cli)
    assert np.array_equal(ply_faces, faces)
    assert np.array_equal(ply_vertices, vertices.astype(np.float32))


def test_street_stream_forgetting_by_default_gives_imr_runs_triangles(shared_dir, tmp_path, run_imr):
    """engine.forget auto: the street stream travels, the engine hands its surface out in parts
    and the module keeps them: its mesh holds imr run's triangles (imr run writes them in the
    order the parts became final, the module in the canonical order)."""
    stream = street_stream(shared_dir)
    engine = imr.Engine()
    for kf in imr.read_slam_json(stream):
        engine.add_keyframe(kf)
    engine.write(tmp_path / "py" / "mesh.ply")
    job = write_job(tmp_path / "job.json", {
        "sequences": [stream], "input": {"format": "slam_json"},
        "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
        "output": {"directory": str(tmp_path / "cli"), "formats": ["ply"]}})
    r = run_imr("run", "-q", job)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.load(open(tmp_path / "cli" / "report.json"))
    stats = engine.stats()
    assert report["engine"]["forget"]["on_from_update"] > 1
    assert stats["forget"]["on_from_update"] == report["engine"]["forget"]["on_from_update"]
    # imr run's count has the last part (Engine::FinishSurface), the module's live surface none.
    assert stats["forget"]["parts"] + 1 == report["engine"]["forget"]["parts"]

    def triangles(ply):
        v, f = read_binary_ply(ply)
        t = v[f].reshape(len(f), 9)
        return sorted(map(tuple, np.array([np.roll(r.reshape(3, 3), -int(np.lexsort(r.reshape(3, 3).T[::-1])[0]), axis=0).ravel() for r in t]).tolist()))

    cli = triangles((tmp_path / "cli" / "mesh.ply").read_bytes())
    py = triangles((tmp_path / "py" / "mesh.ply").read_bytes())
    assert len(cli) == report["mesh"]["faces"] > 10000
    assert py == cli, "other triangles than imr run's"

def colmap_model(tmp_path, run_imr):
    """A small COLMAP text model: imr's own export of a synthetic run."""
    job = write_job(tmp_path / "export.json", synthetic_job(tmp_path / "export", frames=30))
    r = run_imr("run", "-q", job, "--export-colmap", tmp_path / "model")
    assert r.returncode == 0, r.stdout + r.stderr
    return tmp_path / "model"


def test_colmap_keyframe_by_keyframe_is_imr_meshs_mesh(tmp_path, run_imr):
    model = colmap_model(tmp_path, run_imr)
    engine = imr.Engine()
    reader = imr.read_colmap(model, mode="replay", views_per_keyframe=2)
    n = len(reader)
    for kf in reader:
        assert kf.format == "colmap" and len(kf.cameras) >= 1
        engine.add_keyframe(kf)
    assert engine.keyframes == n > 3
    engine.write(tmp_path / "py.ply")
    r = run_imr("mesh", "-q", "--input", model, "--format", "colmap", "--out", tmp_path / "cli.ply",
                "--set", "input.options.mode=replay", "--set", "input.options.views_per_keyframe=2")
    assert r.returncode == 0, r.stdout + r.stderr
    cli = (tmp_path / "cli.ply").read_bytes()
    assert len(cli) > 1000
    assert (tmp_path / "py.ply").read_bytes() == cli
    # The reader's last keyframe is not the engine's last (imr run casts a source's last
    # keyframe's rays as weights only, and its engine then refuses more): one more, built here.
    vertices, _ = engine.mesh()
    centre = vertices.mean(axis=0)
    cam = imr.Camera(10**6, center=tuple(centre), rotation=np.eye(3), intrinsics=(0, 0, 0, 0))
    engine.add_keyframe(cam, new_ids=np.array([10**9, 10**9 + 1]),
                        new_positions=np.array([centre + (0.0, 0.0, 5.0), centre + (1.0, 0.0, 5.0)]))
    assert engine.keyframes == n + 1


def test_the_example_writes_imr_meshs_bytes(tmp_path, run_imr):
    """host/python/examples/mesh_colmap.py: the README's example, on a model made here, with its
    defaults: it prints the `imr mesh` command whose mesh has its bytes (issue 47: the README
    claimed "the bytes of `imr mesh`", true only with two --set it did not name)."""
    model = colmap_model(tmp_path, run_imr)
    example = os.path.join(os.path.dirname(__file__), "..", "examples", "mesh_colmap.py")
    r = subprocess.run([sys.executable, example, str(model), "--out", str(tmp_path / "ex.ply")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "wrote" in r.stdout and "faces int32" in r.stdout
    said = [line for line in r.stdout.splitlines() if line.startswith("the same bytes as: imr mesh ")]
    assert len(said) == 1, r.stdout
    command = shlex.split(said[0][len("the same bytes as: "):])
    assert command[command.index("--out") + 1] == str(tmp_path / "ex.ply")
    command[command.index("--out") + 1] = str(tmp_path / "cli.ply")
    r = run_imr(*command[1:], "-q")
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "ex.ply").read_bytes() == (tmp_path / "cli.ply").read_bytes()
    # imr mesh's defaults (one keyframe of the whole model) are another mesh: the --set matter.
    r = run_imr("mesh", "-q", "--input", model, "--format", "colmap", "--out", tmp_path / "default.ply")
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "default.ply").read_bytes() != (tmp_path / "ex.ply").read_bytes()


def test_points_behind_their_cameras_fail_as_in_imr_run(tmp_path, run_imr):
    """A stream whose cameras all look the wrong way (each rotation turned 180 degrees about
    the camera's x axis): imr run fails the sequence, the module raises the same message."""
    job = write_job(tmp_path / "export.json", synthetic_job(tmp_path / "export", frames=20))
    r = run_imr("run", "-q", job, "--export-stream", tmp_path / "stream.json")
    assert r.returncode == 0, r.stdout + r.stderr
    stream = json.load(open(tmp_path / "stream.json"))
    flip = np.diag([1.0, -1.0, -1.0])
    for view in stream["views"]:
        view["extrinsic"]["rotation"] = (flip @ np.array(view["extrinsic"]["rotation"])).tolist()
    (tmp_path / "mirrored.json").write_text(json.dumps(stream))
    engine = imr.Engine()
    with pytest.raises(imr.Error) as e:
        for kf in imr.read_slam_json(tmp_path / "mirrored.json"):
            engine.add_keyframe(kf)
        engine.mesh()  # 4 keyframes: held for engine.scale auto until the mesh is asked for
    assert "behind the camera" in str(e.value)
    job = write_job(tmp_path / "job.json", {
        "sequences": [str(tmp_path / "mirrored.json")], "input": {"format": "slam_json"},
        "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
        "output": {"directory": str(tmp_path / "out")}})
    r = run_imr("run", job)
    assert r.returncode != 0
    assert str(e.value) in r.stdout, (str(e.value), r.stdout)


def test_reader_errors_are_the_clis(tmp_path, run_imr):
    """A broken SLAM JSON file: the reader's message is the one imr run prints."""
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"slam_data_version": "0.3", "root_path": "", "intrinsics": [],
                               "views": [{"viewId": 0, "id_intrinsic": 3, "filename": "a.png",
                                          "extrinsic": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                                                        "center": [0, 0, 0]},
                                          "observations": []}]}))
    with pytest.raises(imr.Error) as e:
        for kf in imr.read_slam_json(bad):
            pass
    message = str(e.value)
    assert str(bad) in message
    job = write_job(tmp_path / "job.json", {
        "sequences": [str(bad)], "input": {"format": "slam_json"},
        "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
        "output": {"directory": str(tmp_path / "out")}})
    r = run_imr("run", job)
    assert r.returncode != 0
    assert message in r.stdout, (message, r.stdout)
    # imr.run raises with the same words.
    with pytest.raises(imr.SequenceError) as e2:
        imr.run(job)
    assert str(e2.value) == message and e2.value.sequence == "bad.json"
    # A missing file, and bad reader options.
    with pytest.raises(imr.Error, match="no such file"):
        imr.read_slam_json(tmp_path / "absent.json")
    with pytest.raises(ValueError, match="input.options.views_per_keyframe"):
        imr.read_slam_json(bad, views_per_keyframe=0)
    with pytest.raises(ValueError, match="input.format"):
        imr.read("kitti_odometry", tmp_path)
