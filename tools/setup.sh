#!/usr/bin/env bash
# Installs everything imr needs to build and test, from Debian's packages (apt-get) and npm's
# registry (the Khronos glTF validator, <model-viewer>, playwright-core, 3d-tiles-renderer,
# CesiumJS and esbuild: pinned in tools/node/package-lock.json). Idempotent and quick when all is there: apt
# runs only for missing packages. Uses sudo when not root.
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  # toolchain
  g++ cmake ninja-build ccache pkg-config git
  # libraries (DESIGN.md: CGAL, Eigen, OpenCV, Ceres, Boost, nlohmann-json, assimp)
  libcgal-dev libeigen3-dev libopencv-dev libceres-dev libboost-dev libboost-program-options-dev
  nlohmann-json3-dev libassimp-dev
  # SHA-256 of inputs and outputs (host/util/sha256.cc: OpenSSL's libcrypto)
  libssl-dev
  # the imr executable's allocator (host/cli/CMakeLists.txt: 8-10 % of the engine's time)
  libjemalloc-dev
  # tests and benchmarks (valgrind: tools/bench/cache_misses.sh counts cache misses with it)
  libgtest-dev libgmock-dev libbenchmark-dev valgrind
  # the cross-check of `imr evaluate` (tests/evaluate_test: CloudCompare's cloud-to-mesh distance)
  cloudcompare
  # COLMAP's model_analyzer reads imr's --export-colmap (tests/interop_test)
  colmap
  # tests/slurm_test: a one-node Slurm cluster started on localhost (imr submit, array jobs)
  slurm-wlm munge
  # plots of reports (tools/plots/imr_plots.py) and the viewer page's browser test (headless)
  python3-matplotlib chromium
  # the Python module (host/python: pybind11, built for Debian's python3) and its tests (numpy,
  # pytest); python3-open3d (90 MB with its libraries) only shows its example's mesh: not here
  pybind11-dev python3-dev python3-numpy python3-pytest
  # fuzz/* tests: clang with libFuzzer's and the sanitizers' runtimes, llvm-symbolizer for reports
  clang libclang-rt-14-dev llvm-14
)

SUDO=()
if [ "$(id -u)" -ne 0 ]; then SUDO=(sudo); fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
# Node runs the glTF validator in the tests; take Debian's only when no node is there already.
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  missing+=(nodejs npm)
fi

if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  "${SUDO[@]}" apt-get update -q
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "setup: all Debian packages present"
fi

# npm ci only when node_modules is missing or older than the lock file.
if [ ! -d tools/node/node_modules/gltf-validator ] ||
   [ tools/node/package-lock.json -nt tools/node/node_modules/.package-lock.json ]; then
  echo "setup: installing node tools (tools/node)"
  npm ci --prefix tools/node --no-audit --no-fund --loglevel=error
else
  echo "setup: node tools present"
fi
