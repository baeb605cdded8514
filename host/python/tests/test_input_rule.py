"""The open rule from the module (issue 44, docs/reliability.md): a FIFO where a file is expected
raises at once, naming it, as imr's CLI refuses it; the module's readers are the host's."""
import os
import subprocess
import sys

import pytest

# Each call runs in a child interpreter under a 5 s watchdog: a reader that waits on the FIFO
# fails the test instead of hanging it.
CALLS = {
    "read_slam_json": "imr.read_slam_json({fifo!r})",
    "read_openmvg": "imr.read_openmvg({fifo!r})",
    "read_colmap": "imr.read_colmap({folder!r})",
    "evaluate_mesh": "imr.evaluate({fifo!r}, truth={fifo!r})",
    "evaluate_truth": "imr.evaluate({mesh!r}, truth={fifo!r})",
    "run_job_file": "imr.run({fifo!r})",
}

CHILD = """
import sys, imr
try:
    {call}
except (imr.Error, ValueError) as e:
    print(e)
    sys.exit(3)
sys.exit(0)
"""


@pytest.mark.parametrize("name", sorted(CALLS))
def test_a_fifo_is_refused_at_once_naming_it(tmp_path, name):
    folder = tmp_path / "model"
    folder.mkdir()
    if name == "read_colmap":
        for f in ("cameras.txt", "images.txt", "points3D.txt"):
            os.mkfifo(folder / f)
        fifo = str(folder / "cameras.txt")
    else:
        fifo = str(tmp_path / ("in.ply" if name.startswith("evaluate") else "in.json"))
        os.mkfifo(fifo)
    mesh = tmp_path / "mesh.off"
    mesh.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    call = CALLS[name].format(fifo=fifo, folder=str(folder), mesh=str(mesh))
    try:
        r = subprocess.run([sys.executable, "-c", CHILD.format(call=call)], capture_output=True,
                           text=True, timeout=5, env=os.environ.copy())
    except subprocess.TimeoutExpired:
        pytest.fail(f"{call} still running after 5 s: it waits on the FIFO")
    assert r.returncode == 3, (r.returncode, r.stdout, r.stderr)
    assert f"{fifo}: is not a regular file (a FIFO)" in r.stdout, r.stdout
