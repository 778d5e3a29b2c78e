#!/usr/bin/env python3
"""Ground-truth point clouds for the PAC-NeRF protocol on PhysFlow's two "fluids".

PhysFlow's release of PAC-NeRF scenes holds `pcd/<k>.ply`: the object's point cloud at
frame k - 1, in the world frame. This script writes them for the scenes in
tests/fixtures/datasets/physflow_fluids/ from the trajectories PhysFlow's own solver computed
(`expected/<scene>/trajectory.npz`, positions in PhysFlow's simulation box), mapped back to
the world frame with PhysFlow's normalisation :

    x_sim = scale * (R x_world - mean) + (1, 1, 1)

with R the product of the config's `rotation_degree` / `rotation_axis` rotations (right-handed,
applied in list order) and mean the centre of the bounding box of the rotated simulated
Gaussians.

The simulated Gaussians are PhysFlow's: opacity above `opacity_threshold` and within
0.5 / n_grid of a point of moving_part_points.ply. The mapping is checked first: they land on
PhysFlow's initial particle positions to 1e-5. Output: expected/<scene>/pcd/1.ply ... <T>.ply (binary
little-endian, float x y z). numpy only.

    python3 scripts/make_fluid_eval_fixtures.py [FIXTURE_DIR]
"""
import json
import os
import sys

import numpy as np


def read_ply(path):
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert header[1] == "format binary_little_endian 1.0", header[1]
    n = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))
    props = [l.split()[2] for l in header if l.startswith("property float")]
    assert props[:3] == ["x", "y", "z"] and all(l.split()[1] == "float" for l in header
                                                  if l.startswith("property")), props
    rows = np.frombuffer(data[end:end + 4 * n * len(props)], dtype="<f4").reshape(n, len(props))
    return {p: rows[:, i].astype(np.float64) for i, p in enumerate(props)}


def xyz(ply):
    return np.stack([ply["x"], ply["y"], ply["z"]], axis=1)


def write_xyz(path, pts):
    pts = np.ascontiguousarray(pts, dtype="<f4")
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n" % len(pts))
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(pts.tobytes())


def axis_rotation(axis, deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def scene(root, name):
    model = os.path.join(root, "model", "phys_dreamer", name)
    traj = np.load(os.path.join(root, "expected", name, "trajectory.npz"))
    scale = float(traj["scale"][0])
    with open(os.path.join(root, "config", "phys_dreamer", name + "_config.json")) as f:
        cfg = json.load(f)
    g = read_ply(os.path.join(model, "point_cloud", "iteration_30000", "point_cloud.ply"))
    opacity = 1.0 / (1.0 + np.exp(-g["opacity"]))
    pts = xyz(g)[opacity > cfg.get("opacity_threshold", 0.02)]
    moving = xyz(read_ply(os.path.join(model, "moving_part_points.ply")))
    near = np.sqrt(((pts[:, None, :] - moving[None, :, :]) ** 2).sum(-1)).min(axis=1)
    rot = np.eye(3)
    for deg, axis in zip(cfg.get("rotation_degree", []), cfg.get("rotation_axis", [])):
        rot = axis_rotation(axis, deg) @ rot
    sim = pts[near <= 0.5 / cfg["n_grid"]] @ rot.T
    mean = 0.5 * (sim.min(axis=0) + sim.max(axis=0))
    to_sim = scale * (sim - mean) + 1.0
    init = traj["mpm_init_pos_sim"].astype(np.float64)
    assert len(init) == len(to_sim), (len(init), len(to_sim))
    # Every moving point lands on one of PhysFlow's initial particles, and back.
    d2 = ((to_sim[:, None, :] - init[None, :, :]) ** 2).sum(-1)
    worst = max(np.sqrt(d2.min(axis=1)).max(), np.sqrt(d2.min(axis=0)).max())
    assert worst < 1e-5, "%s: normalisation off by %g" % (name, worst)
    out = os.path.join(root, "expected", name, "pcd")
    os.makedirs(out, exist_ok=True)
    pos = traj["pos_sim"].astype(np.float64)
    for k in range(pos.shape[0]):
        world = ((pos[k] - 1.0) / scale + mean) @ rot
        write_xyz(os.path.join(out, "%d.ply" % (k + 1)), world)
    print("%s: %d frames of %d points, scale %.6f, mean %s, mapping checked to %.1e"
          % (name, pos.shape[0], pos.shape[1], scale, np.round(mean, 6).tolist(), worst))


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        here, "..", "tests", "fixtures", "datasets", "physflow_fluids")
    for name in ["ref_paste", "ref_drop"]:
        scene(root, name)


if __name__ == "__main__":
    main()
