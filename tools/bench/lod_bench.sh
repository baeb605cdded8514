#!/bin/bash
# Levels of detail of the tiles (issue 46 item 2; docs/tiles.md): the dense street of
# configs/dense-street.json driven with forgetting and tiles, with output.tiles.lod on and off.
# Prints, from report.json and tileset.json: the leaves and the levels of detail per level, the
# bytes a view from far loads (the first content down each branch of the tree: what
# 3d-tiles-renderer asks for from 30 radii, tests/tiles_browser_test) over the leaves' bytes,
# LOD's seconds and their share of the run's wall time, the coarse content held at most, the
# tileset's size and rewrite bytes per tile (finished subtrees are external tilesets), and
# whether the merged tiles are the same bytes with and without LOD.
#   tools/bench/lod_bench.sh [FRAMES (2000)] [IMR (build/bin/imr)]
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
frames=${1:-2000}
imr=${2:-$root/build/bin/imr}
work=$(mktemp -d /tmp/imr-lod-bench-XXXXXX)
for lod in true false; do
  python3 - "$root/configs/dense-street.json" "$work/$lod" "$frames" "$lod" > "$work/job-$lod.json" <<'P'
import json, sys
c = json.load(open(sys.argv[1]))
job = {"sequences": ["street"], "input": c["input"], "engine": {"forget": True},
       "pipeline": c["pipeline"],
       "output": {"directory": sys.argv[2], "formats": [], "tiles": {"lod": sys.argv[4] == "true"}}}
job["input"]["options"]["frames"] = int(sys.argv[3])
job["input"]["options"]["keep_truth"] = False
print(json.dumps(job))
P
  /usr/bin/time -f "%e" -o "$work/wall-$lod" "$imr" run -q --no-viewer "$work/job-$lod.json" > /dev/null
  "$imr" tiles merge "$work/$lod" --out "$work/merged-$lod.ply" > /dev/null
done
python3 - "$work" "$frames" <<'P'
import json, os, sys, hashlib
work, frames = sys.argv[1], sys.argv[2]
d = os.path.join(work, "true")
# The first content down each branch: what a view from far draws. A level of detail's subtree
# (an external tileset, tiles/lod_NNNNNN.json) stands for its root's content.
def first(n, base=""):
    if "content" in n:
        u = base + n["content"]["uri"]
        if u.endswith(".json"): return first(json.load(open(os.path.join(d, u)))["root"], os.path.dirname(u) + "/")
        return [u]
    return [u for c in n.get("children", []) for u in first(c, base)]
r = json.load(open(os.path.join(d, "report.json")))["tiles"]
ts = json.load(open(os.path.join(d, "tileset.json")))
far = first(ts["root"])
far_bytes = sum(os.path.getsize(os.path.join(d, u)) for u in far)
wall = {k: float(open(os.path.join(work, "wall-" + k)).read().split()[-1]) for k in ("true", "false")}
lod = r["lod"]
md5 = {k: hashlib.md5(open(os.path.join(work, "merged-%s.ply" % k), "rb").read()).hexdigest() for k in ("true", "false")}
print(f"dense street, {frames} frames, forgetting and tiles (lod on / off):")
print(f"  tiles per level (leaves first): {lod['tiles_per_level']}, {lod['gathered']} nodes gathered")
print(f"  leaves {r['count']} tiles, {r['bytes']/1e6:.2f} MB, {r['triangles']} triangles; levels of detail "
      f"{lod['count']} tiles, {lod['bytes']/1e6:.2f} MB, {lod['triangles']} triangles")
print(f"  a view from far loads {len(far)} tile(s), {far_bytes} bytes: {100.0*far_bytes/r['bytes']:.1f} % of the leaves' bytes (target <= 10 %)")
print(f"  LOD {lod['seconds']:.2f} s of the run's {wall['true']:.1f} s wall ({100.0*lod['seconds']/wall['true']:.1f} %, target <= 20 %); "
      f"the run without LOD {wall['false']:.1f} s; coarse content held at most {lod['pending_triangles_peak']} triangles")
tiles = r["count"] + lod["count"]
print(f"  tileset.json at the end {os.path.getsize(os.path.join(d, 'tileset.json'))} bytes; {r['tileset_writes']} versions, "
      f"{r['tileset_bytes']} bytes in all ({r['tileset_bytes'] / max(1, tiles):.0f} per tile); subtrees "
      f"{lod.get('subtree_bytes', 0)} bytes (written once)")
print(f"  merged tiles with and without LOD: {'the same bytes' if md5['true'] == md5['false'] else 'DIFFER'} ({md5['true']})")
P
echo "(work folder: $work)"
