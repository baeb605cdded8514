#!/usr/bin/env python3
"""Writes the committed seed corpus of the fuzzers (tests/fuzz/corpus/<name>/): small,
hand-made, valid or nearly valid inputs of each format, so that fuzzing starts deep in the
readers. Deterministic; run from anywhere: tools/fuzz/make_seeds.py. The job corpus also takes
configs/*.json as they are."""
import json
import math
import pathlib
import shutil
import struct

ROOT = pathlib.Path(__file__).resolve().parents[2]
CORPUS = ROOT / "tests" / "fuzz" / "corpus"
SEP = "\n@@@@\n"

R1 = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
R2 = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]


def put(name, target, data):
    d = CORPUS / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data if isinstance(data, bytes) else data.encode())


def job():
    for cfg in sorted((ROOT / "configs").glob("*.json")):
        put(cfg.name, "job", cfg.read_bytes())
    put("minimal.json", "job", json.dumps({
        "sequences": ["street"], "input": {"format": "synthetic", "options": {"frames": 3}},
        "pipeline": [{"kind": "weight_policy", "plugin": "org.imr.policy.nearest"}],
        "output": {"directory": "runs/{sequence}", "formats": ["ply"]}}))
    put("bad_types.json", "job", '{"sequences": "x", "engine": {"window": "w"}, "output": []}')
    put("nested.json", "job", "[" * 64 + "]" * 64)


def openmvg():
    def view(i, pose):
        return {"key": i, "value": {"ptr_wrapper": {"id": 2147483648 + i, "data": {
            "local_path": "", "filename": "v%d.png" % i, "width": 640, "height": 480,
            "id_view": i, "id_intrinsic": 0, "id_pose": pose}}}}
    scene = {
        "sfm_data_version": "0.3", "root_path": "/images",
        "views": [view(1, 1), view(2, 2), view(3, 4294967295), view(4, 4)],
        "intrinsics": [{"key": 0, "value": {"polymorphic_id": 2147483649,
                        "polymorphic_name": "pinhole_radial_k3", "ptr_wrapper": {
                            "id": 2147483652, "data": {"width": 640, "height": 480,
                                                       "focal_length": 800,
                                                       "principal_point": [320, 240],
                                                       "disto_k3": [0.01, 0, 0]}}}}],
        "extrinsics": [{"key": 1, "value": {"rotation": R1, "center": [1, 2, 3]}},
                       {"key": 2, "value": {"rotation": R2, "center": [3, 2, 3]}},
                       # a third pose: fewer than 3 posed views is "nothing to mesh"
                       {"key": 4, "value": {"rotation": R2, "center": [5, 2, 3]}}],
        "structure": [{"key": 7, "value": {"X": [2, 2.5, 7], "observations": [
            {"key": 1, "value": {"id_feat": 0, "x": [420, 40]}},
            {"key": 2, "value": {"id_feat": 0, "x": [120, 340]}},
            {"key": 3, "value": {"id_feat": 0, "x": [1, 1]}}]}},
            {"key": 8, "value": {"X": [2.5, 2, 8], "observations": [
                {"key": 1, "value": {"id_feat": 1, "x": [300, 100]}},
                {"key": 2, "value": {"id_feat": 1, "x": [200, 300]}},
                {"key": 4, "value": {"id_feat": 0, "x": [100, 300]}}]}}],
        "control_points": []}
    put("scene.json", "openmvg", json.dumps(scene, indent=1))
    scene["intrinsics"][0]["value"]["polymorphic_name"] = "pinhole"
    scene["sfm_data_version"] = "0.2"
    put("scene_v02_pinhole.json", "openmvg", json.dumps(scene))
    scene["structure"][0]["value"]["observations"][0]["key"] = 99  # dangling view id
    put("dangling_view.json", "openmvg", json.dumps(scene))


def colmap():
    q1 = "0.70710678118654757 0 0 -0.70710678118654757"
    cams = "# Camera list\n1 SIMPLE_PINHOLE 640 480 800 320 240\n2 OPENCV 640 480 800 810 320 240 0.01 0 0 0\n"
    imgs = ("# Image list\n1 " + q1 + " -2 1 -3 1 a.png\n420 40 7 10 10 -1\n"
            "2 1 0 0 0 -3 -2 -3 1 b.png\n\n"
            "3 1 0 0 0 -3 -2 -3 2 c.png\n5 5 -1 120 340 7\n")
    pts = "# 3D points\n7 2 2.5 7 255 0 0 0.5 1 0 3 1\n"
    put("scene.txt", "colmap_text", cams + SEP + imgs + SEP + pts)
    put("no_points.txt", "colmap_text", cams + SEP + imgs + SEP + "# empty\n")

    def b(fmt, *v):
        return struct.pack("<" + fmt, *v)
    h = math.sqrt(0.5)
    cams_b = b("Q", 1) + b("iiQQ", 1, 0, 640, 480) + b("ddd", 800, 320, 240)
    imgs_b = b("Q", 3)
    imgs_b += b("i", 1) + b("7d", h, 0, 0, -h, -2, 1, -3) + b("i", 1) + b"a.png\0" + b("Q", 2)
    imgs_b += b("ddq", 420, 40, 7) + b("ddq", 10, 10, -1)
    imgs_b += b("i", 2) + b("7d", 1, 0, 0, 0, -3, -2, -3) + b("i", 1) + b"b.png\0" + b("Q", 0)
    imgs_b += b("i", 3) + b("7d", 1, 0, 0, 0, -3, -2, -3) + b("i", 1) + b"c.png\0" + b("Q", 2)
    imgs_b += b("ddq", 5, 5, -1) + b("ddq", 120, 340, 7)
    pts_b = b("Q", 1) + b("Q", 7) + b("ddd", 2, 2.5, 7) + b("BBB", 255, 0, 0) + b("d", 0.5)
    pts_b += b("Q", 2) + b("ii", 1, 0) + b("ii", 3, 1)
    sep = SEP.encode()
    put("scene.bin", "colmap_binary", cams_b + sep + imgs_b + sep + pts_b)


def slam():
    def view(i, r, c, obs, kf=None):
        v = {"viewId": i, "local_path": "/", "filename": "v%d.png" % i, "width": 640,
             "height": 480, "id_intrinsic": 0, "extrinsic": {"rotation": r, "center": c},
             "observations": obs}
        if kf is not None:
            v["keyframe"] = kf
        return v
    scene = {"slam_data_version": "0.3", "root_path": "",
             "intrinsics": [{"intrinsicId": 0, "value": {"polymorphic_id": 0,
                             "polymorphic_name": "pinhole", "ptr_wrapper": {"data": {
                                 "width": 640, "height": 480, "focal_length": 800,
                                 "principal_point": [320, 240]}}}}],
             "views": [view(1, R1, [1, 2, 3], [{"pointId": 7, "X": [2, 2.5, 7.5], "x": [420, 40]}]),
                       view(2, R2, [3, 2, 3], [{"pointId": 7, "X": [2, 2.5, 7], "x": [120, 340]},
                                               {"pointId": 8, "X": [2.5, 2, 8], "x": [200, 300]}]),
                       view(3, R2, [3, 2, 4], [{"pointId": 8, "X": [2.5, 2.1, 8], "x": [210, 300]},
                                               {"pointId": 7, "X": [2, 2.5, 7], "x": [120, 340]}])]}
    put("scene.json", "slam_json", json.dumps(scene, indent=1))
    for i, v in enumerate(scene["views"]):
        v["keyframe"] = i // 2
    put("keyframes.json", "slam_json", json.dumps(scene))


def kitti():
    p = lambda fx, tx: "%g 0 607.19 %g 0 %g 185.2 0 0 0 1 0" % (fx, tx, fx)
    calib = "".join("P%d: %s\n" % (i, p(718.856, -386.1448 * (i % 2))) for i in range(4))
    calib += "Tr: 0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27\n"
    poses = ("1 0 0 0 0 1 0 0 0 0 1 0\n"
             "1 0 0 0.01 0 1 0 -0.02 0 0 1 0.85\n"
             "0.99995 0 0.0099998 0.02 0 1 0 -0.04 -0.0099998 0 0.99995 1.7\n")
    times = "0.000000e+00\n1.036224e-01\n2.072447e-01\n"
    put("sequence.txt", "kitti_odometry", calib + SEP + poses + SEP + times)
    put("nan_pose.txt", "kitti_odometry",
        calib + SEP + poses.replace("0.85", "nan") + SEP + times)


def kitti_raw():
    cam = ("calib_time: 09-Jan-2012 13:57:47\ncorner_dist: 9.950000e-02\n"
           "S_rect_02: 1.242000e+03 3.750000e+02\n"
           "R_rect_00: 9.999239e-01 9.837760e-03 -7.445048e-03 -9.869795e-03 9.999421e-01 "
           "-4.278459e-03 7.402527e-03 4.351614e-03 9.999631e-01\n"
           "P_rect_00: 7.215377e+02 0 6.095593e+02 0 0 7.215377e+02 1.728540e+02 0 0 0 1 0\n"
           "P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 "
           "7.215377e+02 1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 "
           "2.745884e-03\n")
    velo = ("calib_time: 15-Mar-2012 11:37:16\nR: 7.533745e-03 -9.999714e-01 -6.166020e-04 "
            "1.480249e-02 7.280733e-04 -9.998902e-01 9.998621e-01 7.523790e-03 1.480755e-02\n"
            "T: -4.069766e-03 -7.631618e-02 -2.717806e-01\ndelta_f: 0 0\ndelta_c: 0 0\n")
    imu = ("calib_time: 25-May-2012 16:47:16\nR: 9.999976e-01 7.553071e-04 -2.035826e-03 "
           "-7.854027e-04 9.998898e-01 -1.482298e-02 2.024406e-03 1.482454e-02 9.998881e-01\n"
           "T: -8.086759e-01 3.195559e-01 -7.997231e-01\n")
    poses = ("1 0 0 0 0 1 0 0 0 0 1 0\n"
             "0.9999999 0.0002212 0.0002926 0.0063361 -0.0002211 0.9999999 -0.0002032 0.0000214 "
             "-0.0002926 0.0002031 0.9999999 0.2471275\n"
             "1 0 0 0.01 0 1 0 0 0 0 1 0.5\n")
    stamps = ("2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.074347056\n"
              "2011-09-26 13:02:26.184373201\n")
    oxts = []
    for i in range(3):
        v = [49.011212804408 + i * 1e-6, 8.4228850417969, 112.83492279053, 0.022447, 1e-05,
             -1.2219096732051 + i * 0.001, -3.3256321640686, 1.1384311814592, 3.3714963307759,
             0.15, 0.02, 0.01, 0.013, 0.0, 0.0, -0.01, 0.02, 9.8, 0.001, 0.002, 0.003, 0.004,
             0.005, 0.006, 0.5, 0.4, 4, 10, 4, 4]
        v = ["%.10g" % x for x in v]
        oxts.append(" ".join(v) + "\n")
    put("poses.txt", "kitti_raw", SEP.join([cam, velo, imu, poses, stamps] + oxts))
    put("oxts.txt", "kitti_raw", SEP.join([cam, velo, imu, "", stamps] + oxts))


def middlebury():
    k = "3310.4 0 316.73 0 3325.5 200.55 0 0 1"
    r1 = "1 0 0 0 1 0 0 0 1"
    r2 = "0 1 0 -1 0 0 0 0 1"
    put("par.txt", "middlebury", "2\nview0.png %s %s 0 0 0.6\nview1.png %s %s 0.01 0 0.6\n" %
        (k, r1, k, r2))
    put("one.txt", "middlebury", "1\nview1.png %s %s -0.01 -0.03 0.67\n" % (k, r1))


def geometry():
    ply = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
           "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
           "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n4 0 1 2 3\n")
    put("ascii.ply", "geometry", b"\x00" + ply.encode())
    binhead = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\n"
               "property double y\nproperty double z\nproperty int point_id\nelement face 1\n"
               "property list uchar uint vertex_indices\nend_header\n").encode()
    body = b"".join(struct.pack("<dddi", *v, i) for i, v in enumerate([(0, 0, 0), (1, 0, 0), (0, 1, 0)]))
    body += struct.pack("<BIII", 3, 0, 1, 2)
    put("binary.ply", "geometry", b"\x00" + binhead + body)
    obj = "# obj\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nf 1 2 3\nf 2/1/1 4//1 -2\nf 1 2 3 4\n"
    put("mesh.obj", "geometry", b"\x01" + obj.encode())
    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    idx = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    buf = pos + idx
    gltf = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0, "translation": [1, 0, 0]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
            "buffers": [{"byteLength": len(buf)}],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                            {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                           "min": [0, 0, 0], "max": [1, 1, 0]},
                          {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]}
    import base64
    g = json.loads(json.dumps(gltf))
    g["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
    put("datauri.gltf", "geometry", b"\x02" + json.dumps(g).encode())
    js = json.dumps(gltf).encode()
    js += b" " * (-len(js) % 4)
    glb = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + 8 + len(buf))
    glb += struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(buf), 0x004E4942) + buf
    put("mesh.glb", "geometry", b"\x03" + glb)
    put("cloud.xyz", "geometry", b"\x04# points\n0 0 0\n1,2,3\n// c\n4\t5\t6 7\n")
    put("scan.bin", "geometry", b"\x05" + struct.pack("<8f", 1, 2, 3, 0.5, -4, 5, -1, 0.1))
    off = "OFF\n# a triangle and a coloured quad\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n4 0 1 2 3 255 0 0\n"
    put("mesh.off", "geometry", b"\x06" + off.encode())


def engine():
    # Bytes decoded by engine_fuzz.cc; a few fixed patterns (FuzzedDataProvider reads integers
    # from the end of the input, bytes for coordinates from the front).
    put("zeros", "engine", bytes(64))
    put("ramp", "engine", bytes(range(256)))
    put("ramp3", "engine", bytes((i * 37 + 11) % 256 for i in range(600)))
    put("grid", "engine", bytes(((i * 16) % 250) for i in range(400)) + bytes([6, 16, 2, 16] * 20))


if __name__ == "__main__":
    if CORPUS.exists():
        shutil.rmtree(CORPUS)
    for f in (job, openmvg, colmap, slam, kitti, kitti_raw, middlebury, geometry, engine):
        f()
    for d in sorted(CORPUS.iterdir()):
        print(d.name, len(list(d.iterdir())), sum(f.stat().st_size for f in d.iterdir()))
