"""`pip install host/python` (issue 47 item 4): the package is built outside the source tree, so an
install leaves host/python as it was (setuptools used to leave build/ and imr.egg-info there)."""
import glob
import os
import shutil
import subprocess
import sys

import pytest

import imr

SOURCE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # host/python


def _status(top):
    """git's view of host/python, ignored files included (a build folder under a .gitignore
    rule is still left behind)."""
    r = subprocess.run(["git", "-C", top, "status", "--porcelain", "--ignored", "--", SOURCE],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_pip_install_leaves_the_source_tree_as_it_was(tmp_path):
    if shutil.which("git") is None:
        pytest.skip("no git: cannot tell what the install left in the source tree")
    top = subprocess.run(["git", "-C", SOURCE, "rev-parse", "--show-toplevel"],
                         capture_output=True, text=True, timeout=60)
    if top.returncode != 0:
        pytest.skip("host/python is not in a git work tree")
    top = top.stdout.strip()
    before = _status(top)
    # The build tree this module came from (build/lib/python/imr -> build).
    build = os.path.normpath(os.path.join(os.path.dirname(imr.__file__), "..", "..", ".."))
    env = dict(os.environ, IMR_BUILD_DIR=build, PIP_DISABLE_PIP_VERSION_CHECK="1")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps",
                        "--no-index", "--target", str(tmp_path / "site"), SOURCE],
                       env=env, capture_output=True, text=True, timeout=280)
    assert r.returncode == 0, r.stdout + r.stderr
    assert glob.glob(str(tmp_path / "site" / "imr" / "_imr*.so")), os.listdir(tmp_path / "site")
    assert _status(top) == before
