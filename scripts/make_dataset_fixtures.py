#!/usr/bin/env python3
"""Writes small synthetic scenes in the three dataset layouts r4d-datasets reads, plus
`expected.json` per scene: what an independent implementation of each layout's conventions
(written here, from the original projects' code as tests/fixtures/datasets/README.md records it)
says the loader must find. Pure Python (no numpy), deterministic.

    python3 scripts/make_dataset_fixtures.py tests/fixtures/datasets

Layouts written:
  physflow/model/phys_dreamer/toyphone/   PhysFlow's release (INRIA cameras.json, point_cloud/
                                          iteration_N, moving_part_points.ply, inpaint_points.ply,
                                          images_generated/) + physflow/config/phys_dreamer/
                                          toyphone_config.json (scaled units, a 90-degree
                                          pre-rotation)
  pacnerf/toyball/                        PAC-NeRF all_data.json (OpenGL c2w + intrinsics,
                                          r_<cam>_<frame>.png with frames -1 and -2), a 3DGS
                                          point_cloud.ply and toyball_config.json
  physdreamer/toyplant/                   transforms_train.json, images/, videos/<image>/,
                                          point_cloud.ply, clean_object_points.ply,
                                          moving_part_points.ply
  physdreamer/toyplant_colmap/            the same with COLMAP sparse/0/*.bin instead of
                                          transforms_train.json

The video frames are plain test patterns: tests that fit render their own reference frames from
the true parameters into a copy of the folder.
"""
import json
import math
import os
import struct
import sys
import zlib

SH_DEGREE = 1
N_REST = 3 * ((SH_DEGREE + 1) ** 2 - 1)


class Rng:
    """SplitMix64, so the fixtures do not depend on Python's random module."""

    def __init__(self, seed):
        self.s = seed & (2**64 - 1)

    def next(self):
        self.s = (self.s + 0x9E3779B97F4A7C15) & (2**64 - 1)
        z = self.s
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & (2**64 - 1)
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & (2**64 - 1)
        return ((z ^ (z >> 31)) >> 11) / float(1 << 53)

    def uniform(self, a, b):
        return a + (b - a) * self.next()


def logit(p):
    return math.log(p / (1.0 - p))


def sigmoid(x):
    return 1.0 / (1.0 + math.exp(-x))


def write_png(path, w, h, pixel):
    """8-bit RGB PNG; pixel(x, y) -> (r, g, b) in 0..255."""
    raw = bytearray()
    for y in range(h):
        raw.append(0)
        for x in range(w):
            raw.extend(bytes(pixel(x, y)))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(bytes(raw), 9)) + chunk(b"IEND", b"")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(png)


def pattern(seed):
    return lambda x, y: ((x * 7 + seed * 31) % 256, (y * 11 + seed * 17) % 256, ((x + y) * 5) % 256)


def write_gaussians(path, gs):
    """INRIA 3DGS PLY (binary little endian, float properties)."""
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += ["f_rest_%d" % i for i in range(N_REST)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    head = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(gs)
    head += "".join("property float %s\n" % n for n in names) + "end_header\n"
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(head.encode())
        for g in gs:
            vals = list(g["x"]) + [0.0, 0.0, 0.0] + list(g["dc"]) + [0.01 * i for i in range(N_REST)]
            vals += [g["opacity_logit"]] + list(g["log_scale"]) + list(g["quat"])
            f.write(struct.pack("<%df" % len(vals), *vals))


def write_points(path, pts):
    head = "ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\nend_header\n" % len(pts)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(head)
        for p in pts:
            f.write("%.9g %.9g %.9g\n" % tuple(p))


def f32(v):
    return struct.unpack("<f", struct.pack("<f", v))[0]


def gaussian(x, colour, opacity=0.9, size=0.02):
    return {
        "x": [f32(c) for c in x],
        "dc": [(c - 0.5) / 0.28209479177387814 for c in colour],
        "opacity_logit": f32(logit(opacity)),
        "log_scale": [math.log(size)] * 3,
        "quat": [1.0, 0.0, 0.0, 0.0],
    }


def block(lo, hi, n, colour, rng, jitter=0.0):
    out = []
    for i in range(n[0]):
        for j in range(n[1]):
            for k in range(n[2]):
                t = [(i + 0.5) / n[0], (j + 0.5) / n[1], (k + 0.5) / n[2]]
                x = [lo[a] + (hi[a] - lo[a]) * t[a] + rng.uniform(-jitter, jitter) for a in range(3)]
                out.append(gaussian(x, colour))
    return out


# ---------------------------------------------------------------- linear algebra (3x3, lists)
def matvec(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def transpose(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def normalize(v):
    n = math.sqrt(sum(c * c for c in v))
    return [c / n for c in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def look_at_cv(centre, target, up):
    """Camera-to-world rotation with OpenCV axes (x right, y down, z forward) as columns."""
    z = normalize(sub(target, centre))
    x = normalize(cross(z, up))
    y = cross(z, x)
    return [[x[i], y[i], z[i]] for i in range(3)]


def cv_to_gl(r):
    return [[r[i][0], -r[i][1], -r[i][2]] for i in range(3)]


def axis_rotation(axis, deg):
    # PhysFlow's generate_rotation_matrix (note its pi = 3.1415926).
    t = deg / 180.0 * 3.1415926
    c, s = math.cos(t), math.sin(t)
    if axis == 0:
        return [[1, 0, 0], [0, c, -s], [0, s, c]]
    if axis == 1:
        return [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


# ------------------------------------------------------------------ the projection conventions
def project_inria(cam, p):
    """3DGS (cameras.json): rotation = camera-to-world (columns x right, y down, z forward)."""
    q = matvec(transpose(cam["rotation"]), sub(p, cam["position"]))
    return [cam["fx"] * q[0] / q[2] + cam["width"] / 2.0, cam["fy"] * q[1] / q[2] + cam["height"] / 2.0]


def project_dvgo(c2w, k, p):
    """PAC-NeRF / DVGO: pixel (i, j) centre ray c2w_R ((i + 0.5 - cx) / fx, -(j + 0.5 - cy) / fy, -1);
    returns the continuous coordinate (i + 0.5, j + 0.5) of the pixel the point falls on."""
    r = [row[:3] for row in c2w]
    t = [row[3] for row in c2w]
    q = matvec(transpose(r), sub(p, t))  # OpenGL camera coordinates
    depth = -q[2]
    return [k[0][2] + k[0][0] * q[0] / depth, k[1][2] - k[1][1] * q[1] / depth]


def project_nerf(c2w, f, w, h, p):
    """NeRF transforms (OpenGL camera-to-world) as PhysDreamer's loader hands it to 3DGS."""
    r = [row[:3] for row in c2w]
    t = [row[3] for row in c2w]
    q = matvec(transpose(r), sub(p, t))
    depth = -q[2]
    return [w / 2.0 + f * q[0] / depth, h / 2.0 - f * q[1] / depth]


def quat_to_rot(q):
    w, x, y, z = q
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def rot_to_quat(r):
    # Shepperd's method (r is world-to-camera, proper rotation).
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return [0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s]
    i = max(range(3), key=lambda i: r[i][i])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + r[i][i] - r[j][j] - r[k][k]) * 2
    q = [0.0] * 4
    q[0] = (r[k][j] - r[j][k]) / s
    q[1 + i] = 0.25 * s
    q[1 + j] = (r[j][i] + r[i][j]) / s
    q[1 + k] = (r[k][i] + r[i][k]) / s
    return q


def project_colmap(q, t, k, p):
    r = quat_to_rot(q)
    c = [a + b for a, b in zip(matvec(r, p), t)]
    return [k[0] * c[0] / c[2] + k[2], k[1] * c[1] / c[2] + k[3]]


# ------------------------------------------------------------------------------- the scenes
def physflow_scene(root):
    rng = Rng(1)
    scene = os.path.join(root, "physflow", "model", "phys_dreamer", "toyphone")
    cfg_dir = os.path.join(root, "physflow", "config", "phys_dreamer")
    n_grid = 16
    thres = 0.5 / n_grid
    # A base (static: far from the moving part) and a post on it (moving); world units ~0.5 m.
    base = block([-0.25, -0.25, 0.0], [0.25, 0.25, 0.08], [5, 5, 2], [0.4, 0.3, 0.2], rng)
    post = block([-0.06, -0.06, 0.1], [0.06, 0.06, 0.5], [3, 3, 10], [0.9, 0.2, 0.1], rng, 0.003)
    faint = [gaussian([0.0, 0.0, 0.3 + 0.01 * i], [1, 1, 1], opacity=0.015) for i in range(4)]
    gs = base + post + faint
    moving = [g["x"] for g in post]
    # Two Gaussians placed just inside / just outside the moving-part threshold (world frame).
    top = moving[-1]
    gs.append(gaussian([top[0] + 0.98 * thres, top[1], top[2]], [0, 1, 0]))
    gs.append(gaussian([top[0] + 1.02 * thres, top[1], top[2]], [0, 0, 1]))
    write_gaussians(os.path.join(scene, "point_cloud", "iteration_7000", "point_cloud.ply"), gs)
    write_gaussians(os.path.join(scene, "point_cloud", "iteration_30", "point_cloud.ply"), gs[:10])
    write_points(os.path.join(scene, "moving_part_points.ply"), moving)
    inpaint = [gaussian([0.4, 0.4, 0.0], [0.5, 0.5, 0.5]), gaussian([-0.4, 0.4, 0.0], [0.5, 0.5, 0.5])]
    write_gaussians(os.path.join(scene, "inpaint_points.ply"), inpaint)

    # The moving-part rule and PhysFlow's normalisation, computed here independently.
    kept = [g for g in gs if sigmoid(g["opacity_logit"]) > 0.02]

    def dist(a, b):
        return math.sqrt(sum((a[i] - b[i]) ** 2 for i in range(3)))

    sim = [g for g in kept if min(dist(g["x"], m) for m in moving) <= thres]
    rot = axis_rotation(0, 90.0)
    rotated = [matvec(rot, g["x"]) for g in sim]
    lo = [min(p[a] for p in rotated) for a in range(3)]
    hi = [max(p[a] for p in rotated) for a in range(3)]
    mean = [(lo[a] + hi[a]) / 2 for a in range(3)]
    scale = 1.0 / max(hi[a] - lo[a] for a in range(3))

    w, h = 64, 48
    fx = 60.0
    cams = []
    for i, centre in enumerate([[1.2, -1.0, 0.6], [-1.0, -1.2, 0.5]]):
        r = look_at_cv(centre, [0.0, 0.0, 0.25], [0, 0, 1])
        cams.append({"id": i, "img_name": "view_%d" % i, "width": w, "height": h,
                     "position": centre, "rotation": r, "fx": fx, "fy": fx})
    with open(os.path.join(scene, "cameras.json"), "w") as f:
        json.dump(cams, f, indent=1)
    for t in range(12):
        write_png(os.path.join(scene, "images_generated", "%03d.png" % t), w, h, pattern(t))
    for k in (1, 2):
        write_points(os.path.join(scene, "pcd", "%d.ply" % k), moving)
    config = {
        "opacity_threshold": 0.02, "rotation_degree": [90.0], "rotation_axis": [0],
        "substep_dt": 1e-3, "frame_dt": 2e-2, "opt_frame_dt": 2e-2, "frame_num": 10,
        "n_grid": n_grid, "nu": 0.3, "E": 0.01, "material": "elastic", "density": 1000,
        "g": [0, 0, 0], "grid_v_damping_scale": 0.9999, "rpic_damping": 0.0,
        "boundary_conditions": [
            {"type": "bounding_box"},
            {"type": "cuboid", "point": [1.0, 0.5, 1.0], "size": [0.5, 0.1, 0.5],
             "velocity": [0, 0, 0], "start_time": 0, "end_time": 1e3, "reset": 0},
            {"type": "particle_impulse", "force": [0.02, 0, 0], "point": [1.0, 1.4, 1.0],
             "size": [0.2, 0.12, 0.2], "num_dt": 5, "start_time": 0}],
        "mpm_space_vertical_upward_axis": [0, 1, 0], "default_camera_index": 0,
        "move_camera": False, "reduction": "sum", "lr": {"E": [0.1, 0.001]},
    }
    os.makedirs(cfg_dir, exist_ok=True)
    with open(os.path.join(cfg_dir, "toyphone_config.json"), "w") as f:
        json.dump(config, f, indent=1)
    points = [[0.0, 0.0, 0.25], [0.05, -0.03, 0.4], [-0.1, 0.08, 0.05]]
    expected = {
        "layout": "physflow",
        "gaussians_in_file": len(gs),
        "gaussians_after_opacity_filter": len(kept),
        "simulated_particles": len(sim),
        "static_gaussians": len(kept) - len(sim) + len(inpaint),
        "normalisation": {"rotation": rot, "mean": mean, "scale": scale, "shift": [1.0, 1.0, 1.0]},
        "E_Pa": 0.01 * 1e7, "nu": 0.3, "density_kg_m3": 1000.0,
        "substeps_per_frame": int(2e-2 / 1e-3), "fps": 1.0 / 2e-2, "video_frames": 12,
        "ground_truth": True,
        "projections": [{"camera": c["img_name"], "point": p, "pixel": project_inria(c, p)}
                        for c in cams for p in points],
    }
    with open(os.path.join(scene, "expected.json"), "w") as f:
        json.dump(expected, f, indent=1)


def pacnerf_scene(root):
    rng = Rng(2)
    scene = os.path.join(root, "pacnerf", "toyball")
    ball = []
    for i in range(6):
        for j in range(6):
            for k in range(6):
                x = [(i - 2.5) * 0.04, 0.3 + (j - 2.5) * 0.04, (k - 2.5) * 0.04]
                if sum(c * c for c in [x[0], x[1] - 0.3, x[2]]) < 0.12 ** 2:
                    ball.append(gaussian([c + rng.uniform(-0.002, 0.002) for c in x], [0.2, 0.5, 0.9]))
    write_gaussians(os.path.join(scene, "point_cloud.ply"), ball)
    w = h = 40
    k = [[50.0, 0.0, 19.5], [0.0, 52.0, 20.25], [0.0, 0.0, 1.0]]
    entries, cams = [], []
    for c in range(3):
        a = 2 * math.pi * c / 3
        centre = [1.2 * math.cos(a), 0.6, 1.2 * math.sin(a)]
        r = cv_to_gl(look_at_cv(centre, [0.0, 0.25, 0.0], [0, 1, 0]))
        c2w = [r[i] + [centre[i]] for i in range(3)]
        cams.append(c2w)
        for fr in [-1, -2] + list(range(6)):
            name = "r_%d_%d.png" % (c, fr)
            entries.append({"file_path": "data/" + name, "c2w": c2w, "intrinsic": k})
            write_png(os.path.join(scene, "data", name), w, h, pattern(fr + 3 * c))
    with open(os.path.join(scene, "all_data.json"), "w") as f:
        json.dump(entries, f, indent=1)
    config = {
        "substep_dt": 1e-3, "frame_dt": 1.0 / 24, "frame_num": 6, "n_grid": 16,
        "material": "elastic", "E": 0.005, "nu": 0.3, "density": 800, "g": [0, -9.8, 0],
        "grid_v_damping_scale": 0.9999,
        "boundary_conditions": [{"type": "bounding_box"},
                                {"type": "surface_collider", "point": [1, 0.6, 1], "normal": [0, 1, 0],
                                 "surface": "sticky", "friction": 0.0, "start_time": 0.0, "end_time": 1e3}],
    }
    with open(os.path.join(scene, "toyball_config.json"), "w") as f:
        json.dump(config, f, indent=1)
    points = [[0.0, 0.25, 0.0], [0.1, 0.35, -0.05]]
    expected = {
        "layout": "pacnerf", "gaussians_in_file": len(ball), "simulated_particles": len(ball),
        "static_gaussians": 0, "E_Pa": 0.005 * 1e7, "cameras": 3, "video_frames": 6,
        "fps": 24.0, "substeps_per_frame": int((1.0 / 24) / 1e-3), "ground_truth": False,
        "projections": [{"camera": "r_%d" % c, "point": p, "pixel": project_dvgo(cams[c], k, p)}
                        for c in range(3) for p in points],
    }
    with open(os.path.join(scene, "expected.json"), "w") as f:
        json.dump(expected, f, indent=1)


def physdreamer_scene(root, colmap):
    rng = Rng(3)
    name = "toyplant_colmap" if colmap else "toyplant"
    scene = os.path.join(root, "physdreamer", name)
    pot = block([-0.2, -0.2, 0.0], [0.2, 0.2, 0.15], [4, 4, 2], [0.5, 0.3, 0.2], rng)
    stem = block([-0.03, -0.03, 0.15], [0.03, 0.03, 0.6], [2, 2, 8], [0.1, 0.7, 0.2], rng)
    gs = pot + stem
    write_gaussians(os.path.join(scene, "point_cloud.ply"), gs)
    write_points(os.path.join(scene, "clean_object_points.ply"), [g["x"] for g in gs])
    write_points(os.path.join(scene, "moving_part_points.ply"), [g["x"] for g in stem])
    w, h, angle = 48, 36, 0.9
    f = 0.5 * w / math.tan(0.5 * angle)
    frames, colmap_imgs = [], []
    points = [[0.0, 0.0, 0.3], [0.1, -0.05, 0.5]]
    expected_proj = []
    for i, centre in enumerate([[1.3, 0.2, 0.5], [0.1, 1.3, 0.6]]):
        img = "frame_%05d.png" % (i + 1)
        write_png(os.path.join(scene, "images", img), w, h, pattern(i))
        r_cv = look_at_cv(centre, [0.0, 0.0, 0.3], [0, 0, 1])
        r_gl = cv_to_gl(r_cv)
        c2w = [r_gl[k] + [centre[k]] for k in range(3)] + [[0, 0, 0, 1]]
        frames.append({"file_path": "./images/frame_%05d" % (i + 1), "transform_matrix": c2w})
        w2c = transpose(r_cv)
        t = [-v for v in matvec(w2c, centre)]
        colmap_imgs.append((i + 1, rot_to_quat(w2c), t, img))
        for p in points:
            px = project_nerf(c2w, f, w, h, p)
            if colmap:
                px_c = project_colmap(rot_to_quat(w2c), t, [f, f, w / 2.0, h / 2.0], p)
                assert max(abs(a - b) for a, b in zip(px, px_c)) < 1e-9, (px, px_c)
            expected_proj.append({"camera": img, "point": p, "pixel": px})
        for t_ in range(5):
            write_png(os.path.join(scene, "videos", "frame_%05d_take1" % (i + 1), "%04d.png" % t_), w, h, pattern(t_ + i))
    if colmap:
        sp = os.path.join(scene, "sparse", "0")
        os.makedirs(sp, exist_ok=True)
        with open(os.path.join(sp, "cameras.bin"), "wb") as fh:
            fh.write(struct.pack("<Q", 1))
            fh.write(struct.pack("<iiQQ", 1, 1, w, h))  # PINHOLE
            fh.write(struct.pack("<4d", f, f, w / 2.0, h / 2.0))
        with open(os.path.join(sp, "images.bin"), "wb") as fh:
            fh.write(struct.pack("<Q", len(colmap_imgs)))
            for iid, q, t, img in colmap_imgs:
                fh.write(struct.pack("<i4d3di", iid, *q, *t, 1))
                fh.write(img.encode() + b"\0")
                fh.write(struct.pack("<Q", 1))
                fh.write(struct.pack("<ddq", 1.0, 2.0, -1))
    else:
        with open(os.path.join(scene, "transforms_train.json"), "w") as fh:
            json.dump({"camera_angle_x": angle, "frames": frames}, fh, indent=1)
    expected = {
        "layout": "physdreamer", "gaussians_in_file": len(gs), "simulated_particles": len(gs),
        "static_gaussians": 0, "video_frames": 5, "fps": 30.0, "cameras": 2, "views": 2,
        "projections": expected_proj,
    }
    with open(os.path.join(scene, "expected.json"), "w") as fh:
        json.dump(expected, fh, indent=1)


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else "tests/fixtures/datasets"
    physflow_scene(root)
    pacnerf_scene(root)
    physdreamer_scene(root, colmap=False)
    physdreamer_scene(root, colmap=True)
    print("wrote", root)


if __name__ == "__main__":
    main()
