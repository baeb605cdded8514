#!/usr/bin/env bash
# Builds OpenMVS's InterfaceCOLMAP, DensifyPointCloud, ReconstructMesh and RefineMesh from source
# checkouts the user made, into a cache folder outside the repository, for `imr-bench quality
# --openmvs` only (never CI): RefineMesh on imr's mesh, and the whole pipeline as its own row. OpenMVS is
# AGPL: nothing of it enters this repository; it is only run, as a separate program.
#
#   git clone https://github.com/cdcseacave/openMVS.git   # tested: ce03889 (v2.3.0, master)
#   git clone https://github.com/cdcseacave/VCG.git vcglib  # tested: 658ba36 (the VCG OpenMVS's
#                                                           # docker/buildInDocker.sh clones)
#   tools/bench/peers/build_openmvs.sh OPENMVS_SRC VCGLIB_SRC [CACHE_DIR]
#                                            # default CACHE_DIR: ${XDG_CACHE_HOME:-~/.cache}/imr-peers
#
# Steps: install the Build-Depends from Debian (Boost iostreams/program_options/serialization/
# system, Eigen 3.4, OpenCV, CGAL, libpng/jpeg/tiff, zlib), configure with CUDA, OpenGL (the
# viewer), Python, BreakPad, Ceres and the tests off, build the four executables only (they share
# libMVS; Densify and Reconstruct need no package beyond these). About 8 minutes on 2 cores (JOBS=N: parallel jobs, default nproc). Prints the bin folder last; re-running
# reuses the build (remove CACHE_DIR/openmvs-build to rebuild from other checkouts). Needs root
# (apt) and the machine's configured Debian mirror.
set -euo pipefail

if [[ $# -lt 2 ]]; then
  sed -n '2,17p' "$0" >&2
  exit 2
fi
src="$(cd "$1" && pwd)"
vcg="$(cd "$2" && pwd)"
cache="${3:-${XDG_CACHE_HOME:-$HOME/.cache}/imr-peers}"
jobs="${JOBS:-$(nproc)}"
[[ -f "$src/apps/RefineMesh/RefineMesh.cpp" ]] ||
  { echo "build_openmvs.sh: $src is not an OpenMVS checkout" >&2; exit 2; }
[[ -f "$vcg/vcg/complex/complex.h" ]] ||
  { echo "build_openmvs.sh: $vcg is not a vcglib checkout (no vcg/complex/complex.h)" >&2; exit 2; }
cache="$(realpath -m "$cache")"
repo="$(git -C "$(dirname "$0")" rev-parse --show-toplevel 2>/dev/null || echo /nonexistent)"
case "$cache/" in
  "$repo"/*)
    echo "build_openmvs.sh: the cache folder must be outside the repository: $cache" >&2
    exit 2
    ;;
esac
mkdir -p "$cache"

build="$cache/openmvs-build"
bin="$build/bin"
exes=(InterfaceCOLMAP DensifyPointCloud ReconstructMesh RefineMesh)
all_built=1
for exe in "${exes[@]}"; do [[ -x "$bin/$exe" ]] || all_built=0; done
if [[ $all_built == 1 ]]; then
  echo "$bin"
  exit 0
fi

sudo_cmd=()
if [[ "$(id -u)" != 0 ]]; then sudo_cmd=(sudo); fi

# 1. Build-Depends, only the missing ones.
packages=(cmake ninja-build g++ libboost-iostreams-dev libboost-program-options-dev
          libboost-serialization-dev libboost-system-dev libeigen3-dev libopencv-dev libcgal-dev
          libgmp-dev libmpfr-dev libpng-dev libjpeg-dev libtiff-dev zlib1g-dev)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [[ ${#missing[@]} -gt 0 ]]; then
  echo "build_openmvs.sh: installing ${missing[*]} (log: $cache/openmvs-apt.log)" >&2
  { "${sudo_cmd[@]}" apt-get update -qq &&
    DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq \
      --no-install-recommends "${missing[@]}"; } >"$cache/openmvs-apt.log" 2>&1 ||
    { tail -n 20 "$cache/openmvs-apt.log" >&2; exit 1; }
fi

# 2. Configure: the two tools, nothing optional.
cmake -S "$src" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DVCG_ROOT="$vcg" \
  -DOpenMVS_USE_CUDA=OFF -DOpenMVS_USE_OPENGL=OFF -DOpenMVS_USE_PYTHON=OFF \
  -DOpenMVS_USE_BREAKPAD=OFF -DOpenMVS_USE_CERES=OFF -DOpenMVS_ENABLE_TESTS=OFF \
  -DOpenMVS_USE_OPENMP=ON -DBUILD_SHARED_LIBS=OFF \
  >"$cache/openmvs-cmake.log" 2>&1 || { tail -n 40 "$cache/openmvs-cmake.log" >&2; exit 1; }

# 3. Build the four executables (and the libraries they need).
ninja -C "$build" -j "$jobs" "${exes[@]}" >"$cache/openmvs-build.log" 2>&1 ||
  { tail -n 60 "$cache/openmvs-build.log" >&2; exit 1; }
for exe in "${exes[@]}"; do
  [[ -x "$bin/$exe" ]] || { echo "build_openmvs.sh: no $exe in $bin" >&2; exit 1; }
done
echo "$bin"
