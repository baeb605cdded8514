"""pip packaging of the module built by the CMake tree (nothing is compiled or downloaded here):
imr/__init__.py from here, the extension from build/lib/python/imr, the plugins from
build/lib/imr/plugins (into imr/plugins, where the package looks first).

    cmake --build build --target imr_python
    /usr/bin/python3 -m pip install --no-build-isolation --break-system-packages host/python
    (or, in a venv made with --system-site-packages: pip install --no-build-isolation host/python)

IMR_BUILD_DIR names another build folder (default: ../../build from here). Nothing is written into
the source tree: setuptools' build/ and imr.egg-info go to a temporary folder, removed at exit.
"""
import atexit
import glob
import os
import shutil
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.dist import Distribution

HERE = os.path.dirname(os.path.abspath(__file__))
BUILD = os.path.abspath(os.environ.get("IMR_BUILD_DIR", os.path.join(HERE, "..", "..", "build")))
# setuptools' own scratch (build/, bdist.*, imr.egg-info) out of the source tree (issue 47: `pip
# install host/python` left them there, beside the tracked files).
SCRATCH = tempfile.mkdtemp(prefix="imr-python-setup-")
atexit.register(shutil.rmtree, SCRATCH, True)
SCRATCH_OPTIONS = {"build": {"build_base": os.path.join(SCRATCH, "build")},
                   "egg_info": {"egg_base": SCRATCH}}


class BinaryDistribution(Distribution):
    def has_ext_modules(self):  # a platform wheel: the package holds a compiled extension
        return True


class CopyBuilt(build_py):
    def run(self):
        super().run()
        package = os.path.join(BUILD, "lib", "python", "imr")
        extension = glob.glob(os.path.join(package, "_imr*.so"))
        if not extension:
            raise SystemExit("no built module in %s: run `cmake --build %s --target imr_python` "
                             "first (or set IMR_BUILD_DIR)" % (package, BUILD))
        target = os.path.join(self.build_lib, "imr")
        os.makedirs(os.path.join(target, "plugins"), exist_ok=True)
        for f in extension:
            shutil.copy2(f, target)
        for f in glob.glob(os.path.join(BUILD, "lib", "imr", "plugins", "*.so")):
            shutil.copy2(f, os.path.join(target, "plugins"))


setup(name="imr", version="0.1.0", description="incremental manifold reconstruction with moving points",
      packages=["imr"], cmdclass={"build_py": CopyBuilt}, distclass=BinaryDistribution,
      install_requires=[], python_requires=">=3.9", options=SCRATCH_OPTIONS)
