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


PLY_TYPES = {"float": "<f4", "double": "<f8", "int": "<i4", "uint": "<u4", "uchar": "u1", "char": "i1",
             "short": "<i2", "ushort": "<u2"}


def read_binary_ply(data):
    """(xyz float32 (V, 3), faces (F, 3)) of a binary little-endian PLY of triangles, as
    org.imr.exporter.assimp writes it."""
    import numpy as np
    end = data.index(b"end_header\n") + len(b"end_header\n")
    elements, current = [], None
    for line in data[:end].decode().splitlines():
        w = line.split()
        if w[0] == "format":
            assert w[1] == "binary_little_endian", line
        elif w[0] == "element":
            current = [w[1], int(w[2]), []]
            elements.append(current)
        elif w[0] == "property":
            current[2].append(w[1:])
    offset, vertices, faces = end, None, None
    for name, count, props in elements:
        if name == "vertex":
            dtype = np.dtype([(p[1], PLY_TYPES[p[0]]) for p in props])
            v = np.frombuffer(data, dtype, count, offset)
            offset += dtype.itemsize * count
            vertices = np.stack([v["x"], v["y"], v["z"]], axis=1)
        elif name == "face":
            (_, count_type, index_type, _), = props
            dtype = np.dtype([("n", PLY_TYPES[count_type]), ("i", PLY_TYPES[index_type], 3)])
            f = np.frombuffer(data, dtype, count, offset)
            assert (f["n"] == 3).all()
            offset += dtype.itemsize * count
            faces = f["i"]
    return vertices, faces
