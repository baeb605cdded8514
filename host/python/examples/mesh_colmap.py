#!/usr/bin/env python3
"""Meshes a COLMAP model keyframe by keyframe (its views replayed in order, as a SLAM system would
deliver them), prints how the mesh grows, writes it as `imr mesh` does, and shows it with Open3D
where installed (python3-open3d) and a display is there.

    PYTHONPATH=build/lib/python /usr/bin/python3 host/python/examples/mesh_colmap.py MODEL \
        --out mesh.ply [--views-per-keyframe 4] [--show]

The PLY has the same bytes as the `imr mesh` command it prints:
    imr mesh --input MODEL --format colmap --out mesh.ply \
        --set input.options.mode=replay --set input.options.views_per_keyframe=4
(the views replayed, 4 to a keyframe; `imr mesh` without those --set meshes the model as one
keyframe, its default, and gives another mesh).
"""
import argparse
import os
import shlex
import time

import imr


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", help="a COLMAP sparse model folder (cameras, images, points3D)")
    ap.add_argument("--out", default="mesh.ply", help="the mesh: .ply, .obj, .gltf or .glb")
    ap.add_argument("--views-per-keyframe", type=int, default=4)
    ap.add_argument("--show", action="store_true", help="open an Open3D window (needs a display)")
    args = ap.parse_args()

    imr.set_log_level("warning")
    engine = imr.Engine()  # a job's defaults: engine.scale auto (COLMAP units are unknown)
    keyframes = imr.read_colmap(args.model, mode="replay", views_per_keyframe=args.views_per_keyframe)
    total = len(keyframes)
    start = time.monotonic()
    for kf in keyframes:
        engine.add_keyframe(kf)
        if (kf.index + 1) % max(1, total // 5) == 0 or kf.index + 1 == total:
            vertices, faces = engine.mesh()
            print("keyframe %3d/%d: %5d new points, mesh %6d vertices %6d triangles"
                  % (kf.index + 1, total, len(kf.new_ids), len(vertices), len(faces)))
    stats = engine.stats()
    print("%d keyframes in %.1f s; %d points inserted, %d rays cast; scale factor %g"
          % (stats["keyframes"], time.monotonic() - start, stats["points_inserted"],
             stats["rays_cast"], stats["scale"]["factor"]))
    vertices, faces = engine.mesh()
    print("vertices %s %s, faces %s %s" % (vertices.dtype, vertices.shape, faces.dtype, faces.shape))
    engine.write(args.out)
    print("wrote", args.out)
    print("the same bytes as:", " ".join(shlex.quote(a) for a in [
        "imr", "mesh", "--input", args.model, "--format", "colmap", "--out", args.out,
        "--set", "input.options.mode=replay",
        "--set", "input.options.views_per_keyframe=%d" % args.views_per_keyframe]))

    try:
        import open3d as o3d
    except ImportError:
        print("open3d is not installed (apt-get install python3-open3d): not shown")
        return
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                     o3d.utility.Vector3iVector(faces))
    mesh.compute_vertex_normals()
    print("open3d:", mesh)
    if args.show and os.environ.get("DISPLAY"):
        o3d.visualization.draw_geometries([mesh])


if __name__ == "__main__":
    main()
