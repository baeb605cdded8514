"""Shared fixtures of the Python module's tests (run by ctest: `ctest -R python`)."""
import json
import os
import subprocess

import pytest


def pytest_addoption(parser):
    parser.addoption("--imr", default=None, help="the imr executable (build/bin/imr)")


@pytest.fixture(scope="session")
def imr_exe(request):
    exe = request.config.getoption("--imr")
    if not exe or not os.path.exists(exe):
        pytest.skip("no imr executable given (--imr build/bin/imr)")
    return exe


@pytest.fixture(scope="session")
def shared_dir():
    return os.environ.get("IMR_SHARED_DIR", "")


@pytest.fixture
def run_imr(imr_exe):
    """Runs `imr ARGS...`; returns the CompletedProcess (text)."""
    def run(*args, cwd=None):
        return subprocess.run([imr_exe, *map(str, args)], capture_output=True, text=True, cwd=cwd,
                              timeout=300)
    return run


def write_job(path, job):
    path.write_text(json.dumps(job, indent=2))
    return path


def synthetic_job(out, frames=20, formats=("ply",), engine=None):
    return {"description": "python test", "sequences": ["street"],
            "input": {"format": "synthetic", "options": {"frames": frames}},
            "engine": engine or {},
            "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
            "output": {"directory": str(out), "formats": list(formats)}}
