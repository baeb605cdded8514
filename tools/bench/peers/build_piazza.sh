#!/usr/bin/env bash
# Builds the real-time manifold mesher of Piazza, Romanoni & Matteucci, "Real-time CPU-based
# large-scale 3D mesh reconstruction", RA-L 2018 (public repository
# Enri2077/realtime-manifold-mesh-reconstructor, commit 6e2a6af) into a cache folder outside the
# repository, for imr-bench only (never CI). Its source comes from the team's shared folder as a
# tarball: ${IMR_SHARED_DIR:-<repo>/../shared}/peers/ (see the README there).
#
#   tools/bench/peers/build_piazza.sh [CACHE_DIR]
#       default CACHE_DIR: ${XDG_CACHE_HOME:-~/.cache}/imr-peers/piazza-6e2a6af
#       JOBS=N  parallel compile jobs (default 2: the team's machine is shared)
#
# The peer is GPL-3 (LICENSE.md in the tarball). It is only extracted and built in the cache;
# none of its code is copied into imr. imr-bench finds the binary in this cache (or through
# --piazza PATH / IMR_PIAZZA) and writes the peer's config itself (tools/bench/peers/piazza.cc).
#
# Steps: install the missing Debian packages it needs (Boost filesystem/system besides CGAL,
# OpenCV, Eigen, GMP, MPFR; with sudo when not root), extract the tarball, configure in Release
# with -O2 -std=c++14 (its CMakeLists forces -std=c++11, which CGAL 5.5 rejects; the Release flags
# come later on the command line and win), build the target slamReconstructor (about 3 minutes on
# 2 cores). Prints the binary's path last; re-running reuses the build.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
repo="$(git -C "$here" rev-parse --show-toplevel 2>/dev/null || (cd "$here/../../.." && pwd))"
shared="${IMR_SHARED_DIR:-$repo/../shared}"
name=realtime-manifold-mesh-reconstructor-6e2a6af
tarball="$shared/peers/$name.tar.xz"
cache="${1:-${XDG_CACHE_HOME:-$HOME/.cache}/imr-peers/piazza-6e2a6af}"
jobs="${JOBS:-2}"

cache="$(realpath -m "$cache")"
repo_real="$(realpath "$repo")"
case "$cache/" in
  "$repo_real"/*)
    echo "build_piazza.sh: the cache folder must be outside the repository (GPL-3 code): $cache" >&2
    exit 2
    ;;
esac
mkdir -p "$cache"

src="$cache/src"
build="$cache/build"
bin="$build/slamReconstructor"
if [[ -x "$bin" ]]; then
  echo "$bin"
  exit 0
fi

if [[ ! -f "$tarball" ]]; then
  echo "build_piazza.sh: no $tarball (set IMR_SHARED_DIR to the folder that holds peers/)" >&2
  exit 1
fi

# 1. Debian packages: only the missing ones.
needed=(g++ cmake ninja-build xz-utils libboost-filesystem-dev libboost-system-dev libcgal-dev
        libopencv-dev libeigen3-dev libgmp-dev libmpfr-dev)
missing=()
for p in "${needed[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  sudo_cmd=()
  if [[ "$(id -u)" != 0 ]]; then sudo_cmd=(sudo); fi
  echo "build_piazza.sh: installing ${missing[*]}" >&2
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends \
    "${missing[@]}"
fi

# 2. Source: the tarball's single top folder becomes $src.
if [[ ! -f "$src/CMakeLists.txt" ]]; then
  rm -rf "$src" "$src.tmp"
  mkdir -p "$src.tmp"
  tar -xJf "$tarball" -C "$src.tmp" --strip-components=1
  mv "$src.tmp" "$src"
fi

# 3. Configure and build slamReconstructor only.
cmake -S "$src" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_CXX_FLAGS_RELEASE="-O2 -DNDEBUG -std=c++14" >"$cache/cmake.log" 2>&1 ||
  { tail -n 40 "$cache/cmake.log" >&2; echo "build_piazza.sh: configure failed ($cache/cmake.log)" >&2; exit 1; }
ninja -C "$build" -j "$jobs" slamReconstructor >"$cache/build.log" 2>&1 ||
  { tail -n 40 "$cache/build.log" >&2; echo "build_piazza.sh: build failed ($cache/build.log)" >&2; exit 1; }
[[ -x "$bin" ]] || { echo "build_piazza.sh: no binary at $bin" >&2; exit 1; }
echo "$bin"
