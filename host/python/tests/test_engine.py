"""imr.Engine fed from Python: arrays, options, the policy plugin, memory."""
import sys
import tracemalloc

import numpy as np
import pytest

import imr

from conftest import write_job


def synthetic_engine(frames=20, **options):
    engine = imr.Engine(**options)
    for kf in imr.read("synthetic", "street", frames=frames):
        engine.add_keyframe(kf)
    return engine


def test_mesh_arrays_dtypes_shapes_and_no_copy():
    engine = synthetic_engine()
    vertices, faces = engine.mesh()
    assert vertices.dtype == np.float64 and faces.dtype == np.int32
    assert vertices.ndim == 2 and vertices.shape[1] == 3 and vertices.shape[0] > 100
    assert faces.ndim == 2 and faces.shape[1] == 3 and faces.shape[0] > 100
    assert faces.min() >= 0 and faces.max() < len(vertices)
    assert vertices.flags.c_contiguous and faces.flags.c_contiguous
    # Views of the engine's own buffers (kept alive by the arrays), not copies.
    assert not vertices.flags.owndata and not faces.flags.owndata
    assert vertices.base is not None and faces.base is vertices.base
    v2, f2, ids = engine.mesh(point_ids=True)
    assert ids.dtype == np.int64 and ids.shape == (len(v2),)
    assert np.array_equal(v2, vertices) and np.array_equal(f2, faces)
    assert (ids >= -1).all() and (ids >= 0).any()
    del engine  # the arrays outlive the engine
    assert np.isfinite(vertices).all()


def test_stats_are_the_report_counters():
    engine = synthetic_engine()
    s = engine.stats()
    assert s["keyframes"] == engine.keyframes > 0
    for key in ("rays_cast", "points_inserted", "points_moved", "cells", "cells_in_o", "steiner_points"):
        assert isinstance(s[key], int), key
    assert s["points_inserted"] > 0 and s["cells_in_o"] > 0
    assert s["scale"]["mode"] == "metric"  # synthetic input: metric, as in a job
    assert engine.options()["window"] == 15


@pytest.mark.parametrize("options, words", [
    ({"window": 0}, ["engine.window", "0", ">= 1"]),
    ({"steiner_jitter": 0.5}, ["engine.steiner_jitter", "0.25"]),
    ({"visibility_mode": "fast"}, ["engine.visibility_mode", "exact", "weights", "rays"]),
    ({"regrow_radius": "2"}, ["engine.regrow_radius", "number"]),
    ({"no_such_option": 1}, ["no_such_option"]),
])
def test_bad_options_raise_value_error_naming_option_and_bounds(options, words):
    with pytest.raises(ValueError) as e:
        imr.Engine(**options)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_a_grid_too_large_is_refused_as_imr_validate_refuses_it(tmp_path, run_imr):
    with pytest.raises(ValueError) as e:
        imr.Engine(scale="metric", steiner_spacing=0.01)
    job = write_job(tmp_path / "job.json", {
        "sequences": ["street"], "input": {"format": "synthetic"}, "engine": {"steiner_spacing": 0.01},
        "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
        "output": {"directory": str(tmp_path / "out")}})
    r = run_imr("validate", job)
    assert r.returncode != 0 and str(e.value) in r.stderr, (str(e.value), r.stderr)
    # Metric by default for keyframes built by the caller: refused at construction (issue 44),
    # not at the first keyframe.
    with pytest.raises(ValueError, match="steiner_spacing"):
        imr.Engine(steiner_spacing=0.01)


def test_option_messages_are_imr_validates(tmp_path, run_imr):
    """The same words as `imr validate` prints for the job's engine section."""
    for options in ({"window": 0}, {"camera_path": 100001}, {"min_move_fraction": 2.0}):
        with pytest.raises(ValueError) as e:
            imr.Engine(**options)
        job = write_job(tmp_path / "job.json", {
            "sequences": ["street"], "input": {"format": "synthetic"}, "engine": options,
            "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
            "output": {"directory": str(tmp_path / "out")}})
        r = run_imr("validate", job)
        assert r.returncode != 0
        assert str(e.value) in r.stderr, (str(e.value), r.stderr)


def test_weight_policy_by_plugin_id():
    engine = synthetic_engine(visibility_mode="weights", weight_policy="org.imr.policy.nearest")
    assert engine.stats()["policy_calls"] > 0
    assert len(engine.mesh()[1]) > 100
    # Its params are checked against the plugin's schema.
    with pytest.raises(ValueError) as e:
        imr.Engine(visibility_mode="weights", weight_policy="org.imr.policy.nearest",
                   weight_policy_params={"no_such_param": 1})
    assert "no_such_param" in str(e.value)
    with pytest.raises(ValueError) as e:
        imr.Engine(visibility_mode="weights", weight_policy="org.example.none")
    assert "unknown plugin id" in str(e.value) and "org.imr.policy.nearest" in str(e.value)
    with pytest.raises(ValueError) as e:
        imr.Engine(visibility_mode="weights")
    assert "weight_policy" in str(e.value)


def test_keyframes_built_from_arrays_give_the_readers_mesh():
    """The numpy form of add_keyframe is the same update as the reader's Keyframe."""
    a = imr.Engine()
    b = imr.Engine()
    for kf in imr.read("synthetic", "street", frames=20):
        a.add_keyframe(kf)
        b.add_keyframe(camera=kf.cameras, new_ids=kf.new_ids, new_positions=kf.new_positions,
                       new_cameras=kf.new_cameras, moved_ids=kf.moved_ids,
                       moved_positions=kf.moved_positions, moved_cameras=kf.moved_cameras,
                       removed_ids=kf.removed_ids)
    va, fa = a.mesh()
    vb, fb = b.mesh()
    assert len(fa) > 100
    assert np.array_equal(va, vb) and np.array_equal(fa, fb)


def test_bad_arrays_name_the_argument():
    engine = imr.Engine()
    cam = imr.Camera(0, center=(0, 0, 0))
    with pytest.raises(ValueError, match="new_positions: expected shape \\(2, 3\\)"):
        engine.add_keyframe(cam, new_ids=[1, 2], new_positions=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="new_ids: expected integer ids"):
        engine.add_keyframe(cam, new_ids=np.array([1.5]), new_positions=np.zeros((1, 3)))
    with pytest.raises(ValueError, match="new_ids\\[0\\]: expected an id >= 0"):
        engine.add_keyframe(cam, new_ids=[-1], new_positions=np.zeros((1, 3)))
    with pytest.raises(ValueError, match="new_cameras: needed when the keyframe has 2 cameras"):
        engine.add_keyframe([cam, imr.Camera(1, center=(1, 0, 0))], new_ids=[1],
                            new_positions=[[0, 0, 5]])
    # The engine's own refusal (an unknown camera) is imr.Error, naming the keyframe.
    with pytest.raises(imr.Error, match="keyframe 0"):
        engine.add_keyframe(cam, new_ids=[1], new_positions=[[0, 0, 5]], new_cameras=[7])


LOW = np.array([-15.0, -15.0, 0.0])
SPAN = np.array([30.0, 30.0, 6.0])


def tiny_keyframe(i, rng):
    """One camera on a small loop (the Steiner grid stops growing) and four new points ahead."""
    a = 0.05 * i
    center = (2.0 * np.cos(a), 2.0 * np.sin(a), 1.5)
    # rng.random, not rng.uniform((lo...), (hi...)): numpy 1.24.2's uniform leaks 56 bytes a call
    # with tuple bounds, which this test saw.
    points = rng.random((4, 3)) * SPAN + LOW
    return imr.Camera(i, center=center), np.arange(4 * i, 4 * i + 4), points


def test_a_thousand_keyframes_do_not_grow_pythons_heap():
    rng = np.random.default_rng(1)
    engine = imr.Engine()

    def feed(begin, end):
        for i in range(begin, end):
            cam, ids, pts = tiny_keyframe(i, rng)
            engine.add_keyframe(cam, new_ids=ids, new_positions=pts)

    feed(0, 100)  # warm up: caches, first-use allocations
    tracemalloc.start()
    before, blocks_before = tracemalloc.get_traced_memory()[0], sys.getallocatedblocks()
    feed(100, 1000)
    after, blocks_after = tracemalloc.get_traced_memory()[0], sys.getallocatedblocks()
    tracemalloc.stop()
    assert engine.keyframes == 1000
    assert engine.stats()["points_inserted"] > 1000
    # A reference kept per keyframe (an array, a Camera, a Keyframe) would be 900 objects here:
    # tens of kilobytes at least.
    assert after - before < 16 * 1024, "Python's heap grew by %d bytes" % (after - before)
    assert blocks_after - blocks_before < 200, "%d more blocks" % (blocks_after - blocks_before)
