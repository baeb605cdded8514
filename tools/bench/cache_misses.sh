#!/usr/bin/env bash
# Cache misses of two imr builds on the street stream (issue 18), counted by valgrind's
# cachegrind instead of timed: counts that repeat within 0.3 % (valgrind interleaves the two
# threads a little differently each run), where this shared machine's timings drift by 30 %
# between runs and hide a change of a few percent. The last level is modelled as
# a 512 KB L2 (--LL), the cache a walk or a plan misses when it reaches for a cell, a vertex or a
# ray's state far away; the L3 of the machine holds the whole triangulation of the stream, so
# cachegrind's default (the host's L3) counts almost no misses. Both builds run at once, one per
# core, in threads=2 mode (the plans on), about 9 minutes; valgrind runs the threads one at a
# time on one simulated cache, so the counts are those of all the work, not of either core.
#
#   tools/bench/cache_misses.sh OLD/bin/imr build/bin/imr [FUNCTIONS]
#
# Prints, for each build, the instructions (Ir), L1 data read misses (D1mr) and modelled-L2
# read misses (DLmr) of the whole run and of the FUNCTIONS functions with the most DLmr
# (default 8), and whether the meshes are the same bytes. Needs valgrind (tools/setup.sh
# installs it). The stream: $IMR_SHARED_DIR/data/street-stream (default ../shared beside the
# checkout).
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 A_IMR B_IMR [FUNCTIONS]" >&2
  exit 2
fi
A=$(realpath "$1"); B=$(realpath "$2"); TOP=${3:-8}
command -v valgrind >/dev/null || { echo "cache_misses: valgrind not found" >&2; exit 2; }
source "$(dirname "$0")/common/street_job.sh"
street_setup cache_misses
run() {  # run NAME IMR CORE
  street_job "$1" 2
  # imr run makes a child process per sequence: the engine's counts are the child's.
  taskset -c "$3" valgrind --tool=cachegrind --trace-children=yes --cache-sim=yes \
    --D1=32768,8,64 --LL=524288,8,64 --cachegrind-out-file="$WORK/$1/cg.%p.out" \
    "$2" run -q --force "$WORK/$1/job.json" >"$WORK/$1/log" 2>&1
}
run A "$A" 0 & run B "$B" 1 & wait
for x in A B; do
  # The child's file is the larger one (the parent only waits).
  out=$(ls -S "$WORK/$x"/cg.*.out | head -1)
  echo "== $x ($([ $x = A ] && echo "$A" || echo "$B"))"
  cg_annotate --show=Ir,D1mr,DLmr --sort=DLmr "$out" 2>/dev/null |
    awk -v top="$TOP" '/PROGRAM TOTALS/ {print; next}
                       /file:function/ {f = 1; getline; next}
                       f && NF && n < top {
                         match($0, /.*%\) +/); fn = substr($0, RLENGTH + 1)
                         sub(/^[^:]*:/, "", fn); sub(/\(.*$/, "", fn)  # no file, no arguments
                         print substr($0, 1, RLENGTH) substr(fn, 1, 90); n++}'
done
if cmp -s "$WORK/A/out/mesh.ply" "$WORK/B/out/mesh.ply"; then
  echo "the same mesh bytes"
else
  echo "the meshes differ"
fi
echo "(outputs in $WORK)"
