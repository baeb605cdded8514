"""The write rule from Python (issue 44; host/util/write_rule.h): the module writes only files imr
owns, as every command does (tests/write_rule_cli_test.cc holds the CLI's rows)."""
import pytest

import imr

from conftest import synthetic_job

USERS = b"the user's own bytes\n"


def test_run_leaves_a_users_mesh_in_the_output_folder_alone(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mesh.ply").write_bytes(USERS)
    with pytest.raises(imr.SequenceError) as e:
        imr.run(synthetic_job(out, frames=20))
    assert str(out / "mesh.ply") in str(e.value)
    assert "imr did not write" in str(e.value)
    assert (out / "mesh.ply").read_bytes() == USERS


def test_run_replaces_what_it_wrote(tmp_path):
    out = tmp_path / "out"
    imr.run(synthetic_job(out, frames=20))
    first = (out / "mesh.ply").read_bytes()
    imr.run(synthetic_job(out, frames=20))
    assert (out / "mesh.ply").read_bytes() == first


def _small_engine():
    engine = imr.Engine()
    for kf in imr.read("synthetic", "street", frames=20):
        engine.add_keyframe(kf)
    return engine


def test_engine_write_refuses_a_users_file_and_replaces_its_own(tmp_path):
    engine = _small_engine()
    mine = tmp_path / "mine.ply"
    mine.write_bytes(USERS)
    with pytest.raises(imr.WriteRefused) as e:
        engine.write(str(mine))
    assert isinstance(e.value, PermissionError)
    assert str(mine) in str(e.value) and "imr did not write" in str(e.value)
    assert mine.read_bytes() == USERS
    ours = tmp_path / "ours.ply"
    engine.write(str(ours))
    engine.write(str(ours))  # imr's own: replaced
    assert ours.stat().st_size > 100
    # Changed by the user afterwards: theirs again.
    ours.write_bytes(USERS)
    with pytest.raises(imr.WriteRefused) as e:
        engine.write(str(ours))
    assert "changed since imr wrote it" in str(e.value)
    assert ours.read_bytes() == USERS


def test_engine_write_refuses_a_folder_or_a_fifo(tmp_path):
    import os
    engine = _small_engine()
    (tmp_path / "dir.ply").mkdir()
    with pytest.raises(imr.WriteRefused) as e:
        engine.write(str(tmp_path / "dir.ply"))
    assert "a folder" in str(e.value)
    os.mkfifo(tmp_path / "fifo.ply")
    with pytest.raises(imr.WriteRefused) as e:
        engine.write(str(tmp_path / "fifo.ply"))
    assert "a FIFO" in str(e.value)
