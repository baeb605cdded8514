#!/usr/bin/env bash
# Builds COLMAP 3.8 with CGAL (for `colmap delaunay_mesher`) from Debian's source package into a
# cache folder outside the repository, for `imr-bench peers` only (never CI). Debian's binary
# colmap package is built without CGAL and refuses Delaunay meshing.
#
#   tools/bench/peers/build_colmap.sh [CACHE_DIR]     # default: ${XDG_CACHE_HOME:-~/.cache}/imr-peers
#
# Steps: enable source packages by copying this machine's own apt entries with the deb-src type
# (no mirror address is written anywhere in the repository), install colmap's Build-Depends and
# libcgal-dev, `apt-get source colmap`, configure with CGAL on and GUI/CUDA off, build. About 10
# minutes on 2 cores. Prints the path of the colmap binary last; re-running reuses the build.
# Needs root (apt) and network access to the machine's configured Debian mirror.
set -euo pipefail

cache="${1:-${XDG_CACHE_HOME:-$HOME/.cache}/imr-peers}"
jobs="${JOBS:-$(nproc)}"
mkdir -p "$cache"
cache="$(cd "$cache" && pwd)"
case "$cache" in
  "$(git -C "$(dirname "$0")" rev-parse --show-toplevel 2>/dev/null || echo /nonexistent)"*)
    echo "build_colmap.sh: the cache folder must be outside the repository: $cache" >&2
    exit 2
    ;;
esac

existing="$(ls -d "$cache"/colmap-*/build/src/exe/colmap 2>/dev/null | head -n 1 || true)"
if [[ -n "$existing" && -x "$existing" ]]; then
  echo "$existing"
  exit 0
fi

sudo_cmd=()
if [[ "$(id -u)" != 0 ]]; then sudo_cmd=(sudo); fi

# 1. deb-src entries copied from the machine's own deb entries (deb822 .sources and one-line
#    .list formats), into one file of our own.
src_sources=/etc/apt/sources.list.d/imr-peers-deb-src.sources
src_list=/etc/apt/sources.list.d/imr-peers-deb-src.list
if ! grep -rqsE '^(Types:.*deb-src|deb-src )' /etc/apt/sources.list /etc/apt/sources.list.d/; then
  tmp="$(mktemp)"
  for f in /etc/apt/sources.list.d/*.sources; do
    [[ -f "$f" ]] || continue
    # Keep the stanzas whose Types include "deb"; write them back as deb-src.
    awk 'BEGIN { RS = ""; ORS = "\n\n" }
         /(^|\n)Types:[^\n]*(^| )deb( |\n|$)/ {
           sub(/Types:[^\n]*/, "Types: deb-src"); print }' "$f" >> "$tmp"
  done
  if [[ -s "$tmp" ]]; then "${sudo_cmd[@]}" cp "$tmp" "$src_sources"; fi
  : > "$tmp"
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [[ -f "$f" ]] || continue
    sed -n 's/^deb \(.*\)$/deb-src \1/p' "$f" >> "$tmp"
  done
  if [[ -s "$tmp" ]]; then "${sudo_cmd[@]}" cp "$tmp" "$src_list"; fi
  rm -f "$tmp"
fi
"${sudo_cmd[@]}" apt-get update -qq

# 2. Build-Depends and CGAL.
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get build-dep -y -qq colmap
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends \
  libcgal-dev dpkg-dev cmake ninja-build

# 3. Source package.
cd "$cache"
if ! ls -d colmap-*/ >/dev/null 2>&1; then
  apt-get source colmap
fi
srcdir="$(ls -d "$cache"/colmap-*/ | head -n 1)"
srcdir="${srcdir%/}"

# 4. Configure and build the colmap executable only.
cmake -S "$srcdir" -B "$srcdir/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCGAL_ENABLED=ON -DGUI_ENABLED=OFF -DCUDA_ENABLED=OFF -DTESTS_ENABLED=OFF \
  -DOPENGL_ENABLED=OFF >"$cache/cmake.log" 2>&1 || { tail -n 40 "$cache/cmake.log" >&2; exit 1; }
ninja -C "$srcdir/build" -j "$jobs" colmap_exe >"$cache/build.log" 2>&1 ||
  ninja -C "$srcdir/build" -j "$jobs" >>"$cache/build.log" 2>&1 ||
  { tail -n 40 "$cache/build.log" >&2; exit 1; }
bin="$srcdir/build/src/exe/colmap"
[[ -x "$bin" ]] || { echo "build_colmap.sh: no colmap binary at $bin" >&2; exit 1; }
"$bin" help >/dev/null 2>&1 || true
echo "$bin"
