"""imr: incremental manifold reconstruction with moving points, from Python.

    engine = imr.Engine(regrow_radius=2.0)            # a job's "engine" options, by name
    for kf in imr.read_slam_json("slam.json"):        # or imr.read_colmap("sparse/0", mode="replay")
        engine.add_keyframe(kf)
    vertices, faces = engine.mesh()                   # float64 (V, 3), int32 (F, 3)
    engine.write("mesh.ply")                          # as `imr run` writes it

    reports = imr.run("job.json", overrides={"engine.regrow_radius": 0})
    figures = imr.evaluate("mesh.ply", "gt_points.ply", tau=[0.1, 0.2])

The guide, with every argument: docs/python.md.
"""

import json as _json
import os as _os

from ._imr import (Camera, Engine, Error, Keyframe, SequenceError, WriteRefused,  # noqa: F401
                   __version__, set_log_level)
from . import _imr

__all__ = ["Camera", "Engine", "Error", "Keyframe", "SequenceError", "WriteRefused", "evaluate",
           "read", "read_colmap", "read_openmvg", "read_slam_json", "run", "set_log_level"]


def _plugin_directory():
    """The plugins beside the package (a pip install), else the build tree's (build/lib/python/imr
    -> build/lib/imr/plugins), as imr finds its own next to its executable."""
    here = _os.path.dirname(_os.path.abspath(__file__))
    for d in (_os.path.join(here, "plugins"), _os.path.join(here, "..", "..", "imr", "plugins")):
        if _os.path.isdir(d):
            return _os.path.normpath(d)
    return ""


_imr._set_plugin_directory(_plugin_directory())


def read(format, path, **options):
    """The keyframes of an engine-only input format (colmap, openmvg, slam_json, synthetic), read
    as a job with that input.format and these input.options would read them. An iterator of
    Keyframe objects for Engine.add_keyframe."""
    return _imr.Reader(format, _os.fspath(path), options)


def read_colmap(path, **options):
    """A COLMAP model (sparse/0: cameras, images, points3D as .bin or .txt). Options as a job's
    input.options: mode ("batch": one keyframe; "replay": view by view), views_per_keyframe,
    min_views, order."""
    return read("colmap", path, **options)


def read_openmvg(path, **options):
    """An OpenMVG sfm_data.json (options as read_colmap)."""
    return read("openmvg", path, **options)


def read_slam_json(path, **options):
    """A SLAM JSON 0.3 stream (views_per_keyframe, min_views, min_move)."""
    return read("slam_json", path, **options)


def _override(key, value):
    if not isinstance(key, str) or not key:
        raise ValueError("overrides: keys are paths into the job, e.g. 'engine.regrow_radius'")
    try:
        text = _json.dumps(value, default=lambda o: o.item() if hasattr(o, "item") else o.tolist())
    except (TypeError, AttributeError):
        raise ValueError("overrides: %s: cannot be given as %s" % (key, type(value).__name__)) from None
    return key + "=" + text


def run(job, overrides=None, threads=0):
    """Runs a job (a job file, or a dict as a job file holds) as `imr run JOB --set KEY=VALUE...`
    would, each sequence in this process: its outputs and report.json are written as imr run
    writes them. Returns {sequence: report dict}. A failing sequence raises SequenceError with the
    message imr run prints for it, and so does an output folder holding a report.json or
    manifest.json that this job's sequence did not write (checked for every sequence before
    anything runs: nothing is replaced); an invalid job, or threads outside 0..1024, ValueError
    with the problems imr validate lists. A dict's relative paths are relative to the current
    folder; its {job} is "job", its messages call it "the job (a dict)". Ctrl-C stops the run
    (KeyboardInterrupt) and leaves no half-written output."""
    sets = [_override(k, v) for k, v in (overrides or {}).items()]
    if isinstance(job, dict):
        # The anchor of its relative paths and {job}; no file of that name is read or written.
        return _imr._run(_os.path.join(_os.getcwd(), "job.json"), _json.dumps(job), sets, threads,
                         "the job (a dict)")
    return _imr._run(_os.fspath(job), None, sets, threads, "")


def evaluate(mesh, truth=None, tau=(0.05, 0.1, 0.2, 0.5), **options):
    """`imr evaluate MESH --truth TRUTH --tau ...`: the same figures, as the dict its --out writes.
    mesh: a mesh file, or (vertices, faces) arrays; truth: a point cloud or reference mesh file,
    or an (N, 3) array of points. Arrays are evaluated in memory (no file is written; the report
    and the messages call them "<arrays>" and "<array>"). Options: max_ray_length, crop,
    truth_density, precision_samples, seed, threads, velodyne_seq, scan_step (as imr evaluate's
    flags)."""
    if isinstance(mesh, (tuple, list)) and len(mesh) >= 2 and not isinstance(mesh[0], (str, bytes)):
        mesh_arg = (mesh[0], mesh[1])
    else:
        mesh_arg = _os.fsdecode(mesh)
    if truth is None:
        truth_arg = ""
    elif isinstance(truth, (str, bytes, _os.PathLike)):
        truth_arg = _os.fsdecode(truth)
    else:
        truth_arg = truth
    options["tau"] = [tau] if isinstance(tau, (int, float)) else list(tau)
    return _imr._evaluate(mesh_arg, truth_arg, options)
