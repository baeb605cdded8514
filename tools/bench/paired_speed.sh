#!/usr/bin/env bash
# Paired engine timing of two imr builds on the street stream (issue 18), for a machine whose
# speed drifts between runs: A on core 0 and B on core 1 at the same time, then swapped, for
# each round; then, if --two-cores, A and B alternating on both cores. Prints the engine's
# seconds per phase from each run's report.json and the means, and checks that every mesh is
# the same bytes (--mesh-may-differ: every mesh of each build, for a change that alters the mesh
# on purpose).
#
#   tools/bench/paired_speed.sh OLD/bin/imr build/bin/imr [ROUNDS] [--two-cores] [--mesh-may-differ]
#
# The stream: $IMR_SHARED_DIR/data/street-stream (default ../shared beside the checkout).
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 A_IMR B_IMR [ROUNDS] [--two-cores] [--mesh-may-differ]" >&2
  exit 2
fi
A=$(realpath "$1"); B=$(realpath "$2"); ROUNDS=${3:-2}; TWO=""; EACH=""
for flag in "${@:4}"; do
  case $flag in
    --two-cores) TWO=$flag ;;
    --mesh-may-differ) EACH=1 ;;
    *) echo "paired_speed: unknown option $flag" >&2; exit 2 ;;
  esac
done
source "$(dirname "$0")/common/street_job.sh"
street_setup paired_speed
job() { street_job "$@"; }  # job NAME THREADS
report() {  # report NAME LABEL
  python3 - "$WORK/$1/out/report.json" "$2" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["engine"]["seconds"]
print("%-12s total %6.2f  cast %5.2f  move %5.2f  shrink %5.2f" %
      (sys.argv[2], s["total"], s["cast"], s["move"], s["shrink"]))
PY
}
run() {  # run CORES IMR NAME
  taskset -c "$1" "$2" run -q --force --no-viewer "$WORK/$3/job.json" > "$WORK/$3/log" 2>&1 ||
    { echo "paired_speed: $2 failed, see $WORK/$3/log" >&2; exit 1; }
}
job A 1; job B 1
same() {  # every mesh against the first one (of its build, with --mesh-may-differ)
  local ref="$WORK/first.ply"
  [ -n "$EACH" ] && ref="$WORK/first-${1:0:1}.ply"
  [ -f "$ref" ] || cp "$WORK/$1/out/mesh.ply" "$ref"
  cmp -s "$ref" "$WORK/$1/out/mesh.ply" || { echo "paired_speed: $1's mesh differs" >&2; exit 1; }
}
echo "one core each, at the same time (A = $A, B = $B)"
for r in $(seq 1 "$ROUNDS"); do
  run 0 "$A" A & pid=$!; run 1 "$B" B; wait $pid
  report A "A core 0"; report B "B core 1"; same A; same B
  run 1 "$A" A & pid=$!; run 0 "$B" B; wait $pid
  report A "A core 1"; report B "B core 0"; same A; same B
done | tee "$WORK/one.txt"
if [ "$TWO" = "--two-cores" ]; then
  job A2 0; job B2 0
  echo "both cores, alternating"
  for r in $(seq 1 "$ROUNDS"); do
    run 0,1 "$A" A2; report A2 "A two cores"; same A2
    run 0,1 "$B" B2; report B2 "B two cores"; same B2
  done | tee "$WORK/two.txt"
fi
python3 - "$WORK" "$EACH" <<'PY'
import re, sys, os
same = "every mesh of each build the same bytes (A's and B's may differ)" if sys.argv[2] else \
    "every mesh the same bytes"
for f in ("one.txt", "two.txt"):
    p = os.path.join(sys.argv[1], f)
    if not os.path.exists(p): continue
    t = {}
    for line in open(p):
        m = re.match(r"(A|B)\S*.*total\s+([\d.]+)", line)
        if m: t.setdefault(m.group(1), []).append(float(m.group(2)))
    if "A" in t and "B" in t:
        a, b = sum(t["A"]) / len(t["A"]), sum(t["B"]) / len(t["B"])
        print("%s: mean A %.2f s, B %.2f s (B/A %.3f); %s" %
              ("one core" if f == "one.txt" else "two cores", a, b, b / a, same))
PY
rm -rf "$WORK"
