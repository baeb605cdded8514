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
import tempfile as _tempfile

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
    message imr run prints for it; an invalid job ValueError with the problems imr validate lists.
    A dict's relative paths are relative to the current folder; its {job} is "job". Ctrl-C stops
    the run (KeyboardInterrupt) and leaves no half-written output."""
    sets = [_override(k, v) for k, v in (overrides or {}).items()]
    if isinstance(job, dict):
        return _imr._run(_os.path.join(_os.getcwd(), "job.json"), _json.dumps(job), sets, threads)
    return _imr._run(_os.fspath(job), None, sets, threads)


def _write_mesh(vertices, faces, path):
    import numpy as np
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError("mesh: vertices: expected shape (V, 3), got %s" % (v.shape,))
    if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
        raise ValueError("mesh: faces: expected integers of shape (F, 3), got %s %s" % (f.dtype, f.shape))
    with open(path, "w") as out:  # ASCII OFF at full precision: the same doubles back
        out.write("OFF\n%d %d 0\n" % (len(v), len(f)))
        for x in v:
            out.write("%r %r %r\n" % (float(x[0]), float(x[1]), float(x[2])))
        for t in f:
            out.write("3 %d %d %d\n" % (t[0], t[1], t[2]))


def _write_points(points, path):
    import numpy as np
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError("truth: expected points of shape (N, 3), got %s" % (p.shape,))
    np.savetxt(path, p, fmt="%.17g")


def evaluate(mesh, truth=None, tau=(0.05, 0.1, 0.2, 0.5), **options):
    """`imr evaluate MESH --truth TRUTH --tau ...`: the same figures, as the dict its --out writes.
    mesh: a mesh file, or (vertices, faces) arrays; truth: a point cloud or reference mesh file,
    or an (N, 3) array of points. Options: max_ray_length, crop, truth_density,
    precision_samples, seed, threads, velodyne_seq, scan_step (as imr evaluate's flags)."""
    with _tempfile.TemporaryDirectory(prefix="imr-evaluate-") as tmp:
        mesh_path = mesh
        if isinstance(mesh, (tuple, list)) and len(mesh) >= 2 and not isinstance(mesh[0], str):
            mesh_path = _os.path.join(tmp, "mesh.off")
            _write_mesh(mesh[0], mesh[1], mesh_path)
        truth_path = "" if truth is None else truth
        if truth is not None and not isinstance(truth, (str, bytes, _os.PathLike)):
            truth_path = _os.path.join(tmp, "truth.xyz")
            _write_points(truth, truth_path)
        options["tau"] = [tau] if isinstance(tau, (int, float)) else list(tau)
        report = _imr._evaluate(_os.fspath(mesh_path), _os.fspath(truth_path), options)
        if mesh_path is not mesh:
            report["mesh"]["path"] = "<arrays>"
        if truth_path is not truth and truth is not None and isinstance(report.get("truth"), dict):
            report["truth"]["path"] = "<array>"
        return report
