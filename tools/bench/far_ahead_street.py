#!/usr/bin/python3
"""engine.scale auto on a street seen far ahead (issue 37 item 2).

Writes a COLMAP model of a camera driving forward down a street 12 units wide (walls 8 high at
y = +-6, the ground at z = 0) that sees it only 70-100 units ahead, meshes it with `imr mesh`
twice: as `auto` chooses and with the lengths the rays alone ask for (scale 5), and prints the
time, the chosen grid, the Steiner points against the model's points, the peak RSS and the share
of the mesh's area within 0.5 of a wall or the ground (a slab around the points scores low).
With --before OTHER_IMR (another build, e.g. of the commit before a change) each row is run with
both and printed side by side, and the issue 47 targets (Steiner points <= 10x the points, wall
<= 5 s, peak RSS <= 300 MB, auto's lengths) are checked for --imr.

  tools/bench/far_ahead_street.py --imr build/bin/imr [--before OTHER_IMR] [--images 177 --points 4217] [--work DIR]
"""
import argparse, json, math, os, random, struct, subprocess, sys, tempfile, time

R = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]  # world -> camera: x right, y down, z ahead (+x)
RAYS_ALONE = {"steiner_spacing": 25, "steiner_margin": 25, "max_ray_length": 200, "shrink_radius": 30,
              "regrow_radius": 10, "camera_path_radius": 50, "fill_holes_perimeter": 80}


def write_model(folder, images, step, points, seed=1):
    rng = random.Random(seed)
    os.makedirs(folder, exist_ok=True)
    cams = [(i * step, 0.0, 1.5) for i in range(images)]
    f, w, h = 1000.0, 1000, 800
    def project(c, p):
        d = [p[k] - c[k] for k in range(3)]
        x = [sum(R[r][k] * d[k] for k in range(3)) for r in range(3)]
        return f * x[0] / x[2] + w / 2, f * x[1] / x[2] + h / 2
    pts, seen = [], [[] for _ in cams]
    while len(pts) < points:
        x, s = rng.uniform(70, images * step + 100), rng.random()
        p = (x, -6.0, rng.uniform(0, 8)) if s < 0.35 else (x, 6.0, rng.uniform(0, 8)) if s < 0.7 \
            else (x, rng.uniform(-6, 6), 0.0)
        p = tuple(c + rng.gauss(0, 0.02) for c in p)
        obs = [i for i, c in enumerate(cams) if 70 <= p[0] - c[0] <= 100]
        if len(obs) < 2:
            continue
        track = []
        for i in obs:
            u, v = project(cams[i], p)
            track.append((i + 1, len(seen[i])))
            seen[i].append((u, v, len(pts) + 1))
        pts.append((p, track))
    # R as a quaternion (w, x, y, z): R is a rotation by 120 degrees about (1, -1, 1) / sqrt(3)
    q = (0.5, 0.5, -0.5, 0.5)
    with open(os.path.join(folder, "cameras.txt"), "w") as fh:
        fh.write(f"1 PINHOLE {w} {h} {f} {f} {w / 2} {h / 2}\n")
    with open(os.path.join(folder, "images.txt"), "w") as fh:
        for i, c in enumerate(cams):
            t = [-sum(R[r][k] * c[k] for k in range(3)) for r in range(3)]
            fh.write(f"{i + 1} {q[0]} {q[1]} {q[2]} {q[3]} {t[0]} {t[1]} {t[2]} 1 img{i:04d}.png\n")
            fh.write(" ".join(f"{u} {v} {pid}" for u, v, pid in seen[i]) + "\n")
    with open(os.path.join(folder, "points3D.txt"), "w") as fh:
        for pid, (p, track) in enumerate(pts, start=1):
            fh.write(f"{pid} {p[0]} {p[1]} {p[2]} 128 128 128 -1 " +
                     " ".join(f"{a} {b}" for a, b in track) + "\n")


def read_ply(path):
    with open(path, "rb") as fh:
        header = []
        while True:
            line = fh.readline().decode().strip()
            header.append(line)
            if line == "end_header":
                break
        nv = int(next(l for l in header if l.startswith("element vertex")).split()[2])
        nf = int(next(l for l in header if l.startswith("element face")).split()[2])
        props, element = [], None
        for l in header:
            if l.startswith("element"):
                element = l.split()[1]
            elif l.startswith("property") and element == "vertex":
                props.append(l.split()[1])
        codes = {"float": "f", "double": "d", "int": "i", "uint": "I", "uchar": "B", "int64": "q"}
        vfmt = "<" + "".join(codes[t] for t in props)
        size = struct.calcsize(vfmt)
        verts = [struct.unpack(vfmt, fh.read(size))[:3] for _ in range(nv)]
        faces = []
        for _ in range(nf):
            n = fh.read(1)[0]
            faces.append(struct.unpack("<" + "i" * n, fh.read(4 * n)))
    return verts, faces


def near_share(path):
    verts, faces = read_ply(path)
    area = near = 0.0
    for f in faces:
        a, b, c = (verts[i] for i in f)
        e1 = [b[k] - a[k] for k in range(3)]
        e2 = [c[k] - a[k] for k in range(3)]
        cr = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
        s = 0.5 * math.sqrt(sum(x * x for x in cr))
        m = [(a[k] + b[k] + c[k]) / 3 for k in range(3)]
        area += s
        near += s if min(abs(m[1] - 6), abs(m[1] + 6), abs(m[2])) < 0.5 else 0.0
    return len(faces), near / area if area else 0.0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--imr", required=True)
    ap.add_argument("--before", help="another imr to run beside it (today's build, before a change)")
    ap.add_argument("--images", type=int, default=177)
    ap.add_argument("--step", type=float, default=0.5, help="distance between images")
    ap.add_argument("--points", type=int, default=4217)
    ap.add_argument("--work", help="folder for the model and meshes (default: a temporary one)")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="far_ahead_")
    model = os.path.join(work, "model")
    write_model(model, a.images, a.step, a.points)
    print(f"model: {model} ({a.images} images {a.step} apart, {a.points} points 70-100 ahead)")
    builds = [("before", a.before), ("now", a.imr)] if a.before else [("now", a.imr)]
    print("| lengths | build | seconds | peak RSS MB | Steiner points | a point | steiner_spacing | "
          "max_ray_length | decided by | faces | area within 0.5 of a wall or the ground |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    missed = []
    for name, sets in (("auto", {}), ("the rays alone (scale 5)", RAYS_ALONE)):
        for build, imr in builds:
            out = os.path.join(work, ("auto" if not sets else "rays") + f"-{build}.ply")
            cmd = [imr, "mesh", "-q", "--force", "--input", model, "--format", "colmap", "--out", out]
            for k, v in sets.items():
                cmd += ["--set", f"engine.{k}={v}"]
            t0 = time.time()
            subprocess.run(cmd, check=True, stderr=subprocess.DEVNULL)
            seconds = time.time() - t0
            report = json.load(open(os.path.join(os.path.splitext(out)[0] + ".imr", "mesh", "report.json")))
            o, s, e = report["engine_options"], report["engine_scale"], report["engine"]
            rss = report.get("memory", {}).get("peak_rss_bytes", 0) / 2**20
            steiner = e["steiner_points"] + e.get("steiner_dropped", 0)
            faces, share = near_share(out)
            print(f"| {name} | {build} | {seconds:.1f} | {rss:.0f} | {steiner} | {steiner / a.points:.1f} | "
                  f"{o['steiner_spacing']:g} | {o['max_ray_length']:g} | "
                  f"{s['decided_by'] if not sets else 'the job'} | {faces} | {share:.3f} |")
            if build == "now" and not sets:
                for what, ok in (("Steiner points <= 10x the points", steiner <= 10 * a.points),
                                 ("wall <= 5 s", seconds <= 5.0), ("peak RSS <= 300 MB", rss <= 300)):
                    if not ok:
                        missed.append(what)
    print("issue 47 targets (auto, --imr): " + ("met" if not missed else "missed: " + ", ".join(missed)))

if __name__ == "__main__":
    sys.exit(main())
