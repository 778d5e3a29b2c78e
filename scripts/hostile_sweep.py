#!/usr/bin/env python3
"""Hostile-input sweep over every `r4d` subcommand.

Generates malformed, extreme and inconsistent inputs (files and option values), runs the
`r4d` binary on each with a per-run timeout and classifies every run:

  typed    exit status != 0 with a message on stderr, no panic          (the wanted outcome)
  ok       exit status 0                                                 (valid or tolerated)
  timeout  still running at the timeout (a hang, or a valid but long run)
  panic    "panicked" on stderr, exit status 101, or killed by a signal (abort, SIGSEGV)
  silent   exit status != 0 with nothing on stderr

Not run by CI (it takes minutes). Usage:

  cargo build --release
  python3 scripts/hostile_sweep.py --bin target/release/r4d --work /tmp/r4d-sweep

It writes WORK/report.json (every run: command, class, exit status, last stderr line) and
prints the counts per class and per subcommand, and every run classed panic, silent or
timeout. Standard library only (Python 3.8+); numpy is not needed.
"""

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

EXTREME_FLOATS = ["0", "-1", "1e-300", "1e300", "nan", "inf", "-inf", "1e38", "abc", ""]
EXTREME_INTS = ["0", "-1", "4294967297", "18446744073709551617", "1e3", "abc", ""]


# ---------------------------------------------------------------- file generators


def npy_bytes(header, body):
    """A version-1 .npy with a raw header (padded as numpy pads it) and body."""
    h = header
    total = 10 + len(h) + 1
    h = h + " " * ((64 - total % 64) % 64) + "\n"
    hb = h.encode("latin1")
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(hb)) + hb + body


def f32s(values):
    return b"".join(struct.pack("<f", v) for v in values)


def video_npy(t, h, w, value=0.5, fortran=False):
    header = "{'descr': '<f4', 'fortran_order': %s, 'shape': (%d, %d, %d, 3), }" % (
        "True" if fortran else "False",
        t,
        h,
        w,
    )
    return npy_bytes(header, f32s([value] * (t * h * w * 3)))


def png_bytes(w, h, gray=128, bit16=False):
    """A gray RGB PNG (8- or 16-bit) written without any imaging library."""
    depth = 16 if bit16 else 8
    px = struct.pack(">H", gray * 257) * 3 if bit16 else bytes([gray] * 3)
    raw = b"".join(b"\x00" + px * w for _ in range(h))

    def chunk(kind, data):
        c = kind + data
        return struct.pack(">I", len(data)) + c + struct.pack(">I", zlib.crc32(c) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, depth, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def ply_ascii(rows, props=("x", "y", "z"), declared=None):
    n = len(rows) if declared is None else declared
    head = "ply\nformat ascii 1.0\nelement vertex %d\n" % n
    head += "".join("property float %s\n" % p for p in props)
    head += "end_header\n"
    return head + "".join(" ".join(str(v) for v in r) + "\n" for r in rows)


def ply_binary(points, props=("x", "y", "z"), declared=None):
    n = len(points) if declared is None else declared
    head = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n
    head += "".join("property float %s\n" % p for p in props)
    head += "end_header\n"
    return head.encode() + b"".join(f32s(p) for p in points)


class Corpus:
    """Hostile files under WORK/corpus, by kind."""

    def __init__(self, root):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.videos = {}  # name -> path (file or folder)
        self.plys = {}
        self.ply_dirs = {}
        self.texts = {}  # generic text / config / json files
        self.mp4s = {}

    def file(self, name, data):
        p = self.root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
        return p

    def build(self, repo):
        r = self.root
        # Generic hostile files (any input flag).
        self.texts = {
            "missing": r / "does-not-exist",
            "empty": self.file("empty.bin", b""),
            "garbage": self.file("garbage.bin", bytes(range(256)) * 7),
            "not_utf8": self.file("not_utf8.txt", b"\xff\xfe\xfd" * 50),
            "json_list": self.file("list.json", "[]"),
            "json_nan": self.file("nan.json", '{"a": NaN}'),
            "json_deep": self.file("deep.json", "[" * 100000 + "]" * 100000),
            "toml_deep": self.file("deep.toml", "a = " + "[" * 100000 + "]" * 100000),
            "toml_empty_table": self.file("empty.toml", "[]\n"),
            "dir": r / "a_folder",
            "dev_zero": Path("/dev/zero"),
        }
        (r / "a_folder").mkdir(exist_ok=True)
        # .npy videos.
        good = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 8, 8, 3), }"
        body = f32s([0.5] * (2 * 8 * 8 * 3))
        v = {
            "npy_ok": video_npy(2, 8, 8),
            "npy_fortran": video_npy(2, 8, 8, fortran=True),
            "npy_255": video_npy(2, 8, 8, value=255.0),
            "npy_negative": video_npy(2, 8, 8, value=-0.5),
            "npy_nan": video_npy(2, 8, 8, value=float("nan")),
            "npy_inf": video_npy(2, 8, 8, value=float("inf")),
            "npy_no_fortran_key": npy_bytes("{'descr': '<f4', 'shape': (2, 8, 8, 3)}", body),
            "npy_extra_key": npy_bytes(good[:-3] + " 'x': 1}", body),
            "npy_list_shape": npy_bytes(good.replace("(2, 8, 8, 3)", "[2, 8, 8, 3]"), body),
            "npy_negative_dim": npy_bytes(good.replace("(2, 8", "(-2, 8"), body),
            "npy_float_dim": npy_bytes(good.replace("(2, 8", "(2.0, 8"), body),
            "npy_lower_false": npy_bytes(good.replace("False", "false"), body),
            "npy_unclosed": npy_bytes(good.rstrip("} ,"), body),
            "npy_trailing_text": npy_bytes(good + " junk", body),
            "npy_int_dtype": npy_bytes(good.replace("<f4", "<i4"), body),
            "npy_big_endian": npy_bytes(good.replace("<f4", ">f4"), body),
            "npy_huge_shape": npy_bytes(good.replace("(2, 8, 8, 3)", "(4611686018427387904, 4, 1, 3)"), body),
            "npy_overflow_dim": npy_bytes(good.replace("(2, 8", "(99999999999999999999999, 8"), body),
            "npy_short_data": npy_bytes(good, body[:-4]),
            "npy_long_data": npy_bytes(good, body + b"\0\0\0\0"),
            "npy_zero_frames": npy_bytes(good.replace("(2, 8", "(0, 8"), b""),
            "npy_2d": npy_bytes(good.replace("(2, 8, 8, 3)", "(384,)"), body),
            "npy_4ch": npy_bytes(good.replace("8, 3)", "6, 4)"), body),
            "npy_bad_magic": b"\x93NUMPX" + npy_bytes(good, body)[6:],
            "npy_version_9": b"\x93NUMPY\x09\x00" + npy_bytes(good, body)[8:],
            "npy_hlen_huge": npy_bytes(good, body)[:8] + b"\xff\xff" + npy_bytes(good, body)[10:],
            "npy_truncated_header": npy_bytes(good, body)[:40],
            "npy_deep_header": npy_bytes("{'descr': " + "(" * 5000 + ")" * 5000 + "}", body),
        }
        for k, data in v.items():
            self.videos[k] = self.file("videos/%s.npy" % k, data)
        # PNG frame folders.
        def frames(name, names_sizes):
            d = r / "videos" / name
            d.mkdir(parents=True, exist_ok=True)
            for fname, (w, h), extra in names_sizes:
                (d / fname).write_bytes(extra if extra is not None else png_bytes(w, h))
            self.videos[name] = d
        frames("png_ok", [("frame_%04d.png" % k, (8, 8), None) for k in range(3)])
        frames("png_unpadded", [("frame_%d.png" % k, (8, 8), None) for k in range(12)])
        frames("png_gap", [("frame_%d.png" % k, (8, 8), None) for k in (0, 1, 2, 4)])
        frames("png_duplicate", [(n, (8, 8), None) for n in ("f_1.png", "f_01.png", "f_2.png")])
        frames("png_sizes", [("frame_0.png", (8, 8), None), ("frame_1.png", (8, 6), None)])
        frames("png_not_png", [("frame_0.png", (8, 8), None), ("frame_1.png", (8, 8), b"not a png")])
        frames("png_empty", [])
        frames("png_16bit", [("frame_%d.png" % k, (8, 8), png_bytes(8, 8, bit16=True)) for k in range(2)])
        frames("png_huge_header", [("frame_0.png", (8, 8), png_bytes(8, 8)[:16] + struct.pack(">II", 100000, 100000) + png_bytes(8, 8)[24:])])
        # MP4s.
        fixtures = repo / "crates" / "video" / "tests" / "fixtures"
        good_mp4 = fixtures / "x264_baseline_30fps.mp4"
        if good_mp4.exists():
            data = good_mp4.read_bytes()
            self.mp4s["mp4_ok"] = self.file("videos/ok.mp4", data)
            self.mp4s["mp4_truncated"] = self.file("videos/truncated.mp4", data[: len(data) // 2])
            self.mp4s["mp4_head"] = self.file("videos/head.mp4", data[:64])
            at = data.find(b"avc1", data.find(b"stsd")) + 4 + 24
            big = bytearray(data)
            big[at : at + 4] = b"\x20\x00\x20\x00"
            self.mp4s["mp4_claims_8k"] = self.file("videos/claims_8k.mp4", bytes(big))
            big[at : at + 2] = b"\xff\xff"
            self.mp4s["mp4_claims_65535"] = self.file("videos/claims_65535.mp4", bytes(big))
        for name in ("hevc.mp4", "mpeg4.mp4"):
            if (fixtures / name).exists():
                self.mp4s["mp4_" + name[:-4]] = fixtures / name
        self.mp4s["mp4_garbage"] = self.file("videos/garbage.mp4", bytes(range(256)) * 40)
        # PLY files.
        pts = [[0.1 * i, 0.2, 0.3] for i in range(5)]
        text = ply_ascii(pts)
        p = {
            "ply_ok": text,
            "ply_cut_in_number": text[:-3],
            "ply_fewer_rows": ply_ascii(pts, declared=8),
            "ply_extra_values": text.replace("0.2 0.3\n", "0.2 0.3 9\n", 1),
            "ply_nan": ply_ascii([[float("nan"), 0, 0]] + pts),
            "ply_inf": ply_ascii([[float("inf"), 0, 0]] + pts),
            "ply_huge_count_ascii": ply_ascii(pts, declared=10**15),
            "ply_huge_count_bin": ply_binary(pts, declared=2**62),
            "ply_bin_short": ply_binary(pts)[:-5],
            "ply_no_xyz": ply_ascii(pts, props=("a", "b", "c")),
            "ply_header_only": "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n",
            "ply_no_end_header": "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
            "ply_list_prop": "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int x\nend_header\n1 2\n",
            "ply_bad_format": text.replace("ascii", "utf8"),
            "ply_far": ply_ascii([[1e30, 1e30, 1e30]] + pts),
        }
        for k, data in p.items():
            self.plys[k] = self.file("ply/%s.ply" % k, data)
        # PLY frame folders.
        def ply_dir(name, files):
            d = r / "plydirs" / name
            d.mkdir(parents=True, exist_ok=True)
            for fname, data in files:
                (d / fname).write_text(data)
            self.ply_dirs[name] = d
        ply_dir("frames_ok", [("frame_%04d.ply" % k, text) for k in range(3)])
        ply_dir("frames_unpadded", [("frame_%d.ply" % k, text) for k in range(12)])
        ply_dir("frames_gap", [("frame_%04d.ply" % k, text) for k in (0, 1, 3)])
        ply_dir("frames_truncated", [("frame_0000.ply", text), ("frame_0001.ply", text[:-3])])
        ply_dir("frames_counts", [("frame_0000.ply", text), ("frame_0001.ply", ply_ascii(pts[:2]))])
        ply_dir("frames_empty", [])
        # Cameras.
        cam = {
            "width": 8, "height": 8, "fx": 10.0, "fy": 10.0, "cx": 4.0, "cy": 4.0,
            "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]],
        }
        cams = {
            "cam_huge": dict(cam, width=10**9, height=10**9),
            "cam_zero": dict(cam, width=0),
            "cam_nan": dict(cam, fx=float("nan")),
            "cam_negative_f": dict(cam, fx=-1.0),
        }
        for k, c in cams.items():
            self.texts[k] = self.file("cams/%s.json" % k, json.dumps([c]).replace("NaN", "NaN"))
        self.texts["cam_empty_list"] = self.file("cams/empty.json", "[]")
        # Simulation configs: the fit fixture with one value made hostile at a time.
        base = (repo / "tests" / "fixtures" / "fit" / "beam_start.toml").read_text()
        self.configs = {"cfg_ok": self.file("cfg/ok.toml", base)}
        subs = {
            "n_grid": ["n_grid = 24", ["n_grid = 0", "n_grid = 1024", "n_grid = 4294967297", "n_grid = -1"]],
            "substep_dt": ["substep_dt = 2e-4", ["substep_dt = 1e-300", "substep_dt = 0.0", "substep_dt = nan", "substep_dt = 1e9"]],
            "substeps": ["substeps_per_frame = 50", ["substeps_per_frame = 0", "substeps_per_frame = 4294967297", "substeps_per_frame = 100000000"]],
            "frames": ["frames = 6", ["frames = 0", "frames = 1000000000", "frames = -3"]],
            "E": ["youngs_modulus_pa = 2e6", ["youngs_modulus_pa = -1", "youngs_modulus_pa = 1e300", "youngs_modulus_pa = nan", "youngs_modulus_pa = 0"]],
            "nu": ["poisson_ratio = 0.3", ["poisson_ratio = 0.5", "poisson_ratio = -1.5", "poisson_ratio = 1e-300"]],
            "rho": ["density_kg_m3 = 1000.0", ["density_kg_m3 = 0", "density_kg_m3 = 1e308"]],
            "material": ['material = "jelly"', ['material = "jello"', "material = 3"]],
            "grid_lim": ["grid_lim = 1.0", ["grid_lim = 0", "grid_lim = 1e300", "grid_lim = -1"]],
            "origin": ["origin = [0.2083333, 0.4375, 0.4375]", ["origin = [5.0, 5.0, 5.0]", "origin = [nan, 0, 0]", "origin = [0.2]"]],
            "length": ["length = 0.5", ["length = 0", "length = -0.5", "length = 1e300"]],
            "typo": ["[time]", ["[tiem]", "[time]\nsubstpes_per_frame = 3"]],
            "dup": ["frames = 6", ["frames = 6\nframes = 7"]],
            "array_table": ["[domain]\ngrid_lim = 1.0\nn_grid = 24", ["domain = [1.0, 24]"]],
            "array_time": ["[time]\nsubstep_dt = 2e-4\nsubsteps_per_frame = 50\nframes = 6", ["time = [2e-4, 50, 6]"]],
            "yield": ["density_kg_m3 = 1000.0", ["density_kg_m3 = 1000.0\nyield_stress_pa = 1e300", "density_kg_m3 = 1000.0\nplastic_viscosity_pa_s = 1e40", "density_kg_m3 = 1000.0\nsoftening = 1e300", "density_kg_m3 = 1e-300"]],
            "cfl": ["youngs_modulus_pa = 2e6", ["youngs_modulus_pa = 1e12"]],
        }
        for key, (old, news) in subs.items():
            for i, new in enumerate(news):
                if old in base:
                    self.configs["cfg_%s_%d" % (key, i)] = self.file("cfg/%s_%d.toml" % (key, i), base.replace(old, new, 1))
        self.configs["cfg_garbage"] = self.texts["garbage"]
        self.configs["cfg_empty_table"] = self.texts["toml_empty_table"]
        self.configs["cfg_deep"] = self.texts["toml_deep"]


# ---------------------------------------------------------------- runs


def runs(c, repo, work):
    """Every (subcommand, label, argv) of the sweep."""
    out = []
    o = lambda name: str(work / "out" / name)  # noqa: E731
    fx = repo / "tests" / "fixtures"
    beam = str(fx / "fit" / "beam_start.toml")
    # metrics: every video against a good one, both ways; then extreme rates.
    ok = str(c.videos["npy_ok"])
    for k, p in list(c.videos.items()) + list(c.mp4s.items()):
        out.append(("metrics", k + " as rendered", ["metrics", "--reference", ok, "--rendered", str(p)]))
        out.append(("metrics", k + " as reference", ["metrics", "--reference", str(p), "--rendered", ok]))
    for k, p in c.texts.items():
        out.append(("metrics", k, ["metrics", "--reference", str(p), "--rendered", ok]))
    for flag in ("--fps", "--reference-fps", "--rendered-fps"):
        for v in EXTREME_FLOATS + ["1e9"]:
            out.append(("metrics", "%s %s" % (flag, v), ["metrics", "--reference", ok, "--rendered", ok, flag, v, "--fps", "30"] if flag != "--fps" else ["metrics", "--reference", ok, "--rendered", ok, flag, v]))
    out.append(("metrics", "lpips garbage", ["metrics", "--reference", ok, "--rendered", ok, "--lpips-weights", str(c.texts["garbage"])]))
    out.append(("metrics", "lpips dev_zero", ["metrics", "--reference", ok, "--rendered", ok, "--lpips-weights", "/dev/zero"]))
    # metrics-trajectory: PLY folders, both ways; --tau and --skip.
    fok = str(c.ply_dirs["frames_ok"])
    for k, p in c.ply_dirs.items():
        out.append(("metrics-trajectory", k, ["metrics-trajectory", "--reference", fok, "--simulated", str(p)]))
        out.append(("metrics-trajectory", k + " as reference", ["metrics-trajectory", "--reference", str(p), "--simulated", fok]))
    for k, p in c.plys.items():
        d = work / "plyone" / k
        d.mkdir(parents=True, exist_ok=True)
        shutil.copy(p, d / "frame_0000.ply")
        shutil.copy(c.plys["ply_ok"], d / "frame_0001.ply")
        out.append(("metrics-trajectory", k, ["metrics-trajectory", "--reference", fok, "--simulated", str(d)]))
    for v in EXTREME_FLOATS + ["1e-300,0.1", ","]:
        out.append(("metrics-trajectory", "--tau " + v, ["metrics-trajectory", "--reference", fok, "--simulated", fok, "--tau", v]))
    for v in EXTREME_INTS:
        out.append(("metrics-trajectory", "--skip " + v, ["metrics-trajectory", "--reference", fok, "--simulated", fok, "--skip", v]))
    # simulate: hostile configs, particles, frames.
    for k, p in c.configs.items():
        out.append(("simulate", k, ["simulate", "--config", str(p), "--out", o("sim_" + k), "--frames", "2"]))
    for k, p in c.plys.items():
        out.append(("simulate", "--particles " + k, ["simulate", "--config", beam, "--particles", str(p), "--out", o("simp_" + k), "--frames", "2"]))
    for v in EXTREME_INTS:
        out.append(("simulate", "--frames " + v, ["simulate", "--config", beam, "--out", o("simf_" + v.replace("/", "_")), "--frames", v]))
    for k in ("empty", "garbage", "json_deep", "json_list", "dev_zero", "dir", "missing"):
        out.append(("simulate", "--physgaussian " + k, ["simulate", "--physgaussian", "--config", str(c.texts[k]), "--out", o("simpg_" + k)]))
    pg = fx / "physgaussian"
    for name in ("jelly_drop", "sand_pile"):
        src = pg / name / "physgaussian_config.json"
        if src.exists():
            text = src.read_text()
            for i, (a, b) in enumerate([('"grid_v_damping_scale"', '"grid_v_damping_scale_typo"'), ("0.", "-1e300.")]):
                if a in text:
                    f = c.file("pg/%s_%d.json" % (name, i), text.replace(a, b, 1))
                    out.append(("simulate", "physgaussian %s %d" % (name, i), ["simulate", "--physgaussian", "--config", str(f), "--out", o("pg_%s_%d" % (name, i)), "--frames", "1"]))
    # fit-trajectory: targets and optimiser options.
    for k, p in c.ply_dirs.items():
        out.append(("fit-trajectory", "--target " + k, ["fit-trajectory", "--config", beam, "--target", str(p), "--params", "E", "--out", o("ft_" + k), "--iters", "1", "--frames", "2"]))
    for flag in ("--lr", "--beta1", "--beta2"):
        for v in EXTREME_FLOATS:
            out.append(("fit-trajectory", "%s %s" % (flag, v), ["fit-trajectory", "--config", beam, "--target", str(c.ply_dirs["frames_gap"]), "--params", "E", "--out", o("ftf"), flag, v]))
    for v in EXTREME_INTS:
        out.append(("fit-trajectory", "--iters " + v, ["fit-trajectory", "--config", beam, "--target", fok, "--params", "E", "--out", o("fti"), "--iters", v]))
    for v in ("E,E", "bogus", "", "E,nu,rho,yield,x"):
        out.append(("fit-trajectory", "--params " + v, ["fit-trajectory", "--config", beam, "--target", fok, "--params", v, "--out", o("ftp")]))
    # render: hostile scenes and cameras; options.
    sh0 = fx / "splat" / "sh0_basic"
    scene = next(iter(sorted(sh0.glob("*.ply"))), None)
    cams = next(iter(sorted(sh0.glob("*camera*.json"))), None)
    scene = str(scene) if scene else str(c.plys["ply_ok"])
    cams = str(cams) if cams else str(c.texts["cam_huge"])
    for k, p in c.plys.items():
        out.append(("render", "--scene " + k, ["render", "--scene", str(p), "--camera", cams, "--out", o("r_%s.png" % k)]))
    for k, p in c.texts.items():
        out.append(("render", "--camera " + k, ["render", "--scene", scene, "--camera", str(p), "--out", o("rc_%s.png" % k)]))
    for v in ("0.5,2,0.5", "1e-300,0,0", "nan,0,0", "1,1", "0,0,0,0"):
        out.append(("render", "--background " + v, ["render", "--scene", scene, "--camera", cams, "--out", o("rb.png"), "--background", v]))
    for v in EXTREME_INTS:
        out.append(("render", "--camera-index " + v, ["render", "--scene", scene, "--camera", cams, "--out", o("ri.png"), "--camera-index", v]))
        out.append(("render", "--fps " + v, ["render", "--scene", scene, "--camera", cams, "--out", o("rf"), "--frames", fok, "--fps", v]))
    for k, p in c.ply_dirs.items():
        out.append(("render", "--frames " + k, ["render", "--scene", scene, "--camera", cams, "--out", o("rs_" + k), "--frames", str(p)]))
    for k, p in c.plys.items():
        out.append(("render", "--frame " + k, ["render", "--scene", scene, "--camera", cams, "--out", o("rfr_%s.png" % k), "--frame", str(p)]))
    # prepare.
    for k, p in c.plys.items():
        out.append(("prepare", "--scene " + k, ["prepare", "--scene", str(p), "--config", str(pg / "jelly_drop" / "physgaussian_config.json"), "--out", o("prep_" + k)]))
    for k, p in c.texts.items():
        out.append(("prepare", "--config " + k, ["prepare", "--scene", scene, "--config", str(p), "--out", o("prepc_" + k)]))
    # segment: float options and hostile inputs.
    for flag in ("--temperature", "--full-visibility", "--background-weight", "--region-tau", "--region-power", "--region-static-power", "--appearance"):
        for v in EXTREME_FLOATS:
            out.append(("segment", "%s %s" % (flag, v), ["segment", "--scene", scene, "--cameras", cams, "--masks", str(c.videos["png_ok"]), "--out", o("seg.json"), flag, v]))
    for flag in ("--k", "--min-cluster", "--rounds"):
        for v in EXTREME_INTS:
            out.append(("segment", "%s %s" % (flag, v), ["segment", "--scene", scene, "--cameras", cams, "--masks", str(c.videos["png_ok"]), "--out", o("seg.json"), flag, v]))
    for k, p in list(c.videos.items())[:12] + list(c.texts.items()):
        out.append(("segment", "--masks " + k, ["segment", "--scene", scene, "--cameras", cams, "--masks", str(p), "--out", o("segm.json")]))
    # fit: on the demo's inputs (when the setup made them) with one input or option made
    # hostile at a time; a tiny fit config keeps a run that is valid short.
    demo = work / "demo" / "inputs"
    fit_cfg = c.file("fit_tiny.toml", 'iters = 1\nfree = ["E"]\nprecision = "f32"\nframes = 3\n[init]\ncandidates = 2\nframes = 2\n[loss.spectral]\npatch = [16, 16]\n')
    d = lambda n: str(demo / n)  # noqa: E731
    fit_base = {"--scene": d("scene.ply"), "--sim": d("sim.toml"), "--particles": d("particles.ply"),
                "--parts": d("parts.json"), "--cameras": d("cameras.json"), "--video": d("reference.npy"),
                "--config": str(fit_cfg)}
    n_fit = [0]

    def fit(label, **over):
        n_fit[0] += 1
        args = dict(fit_base)
        args.update({k.replace("_", "-"): v for k, v in over.items()})
        argv = ["fit", "--out", o("fit_%d" % n_fit[0])]
        for k, v in args.items():
            argv += [k, v]
        out.append(("fit", label, argv))
    for k, p in list(c.videos.items()) + list(c.mp4s.items()):
        fit("--video " + k, **{"--video": str(p)})
    for flag, vals in (("--fps", EXTREME_FLOATS + ["1e9"]), ("--key-frames", EXTREME_INTS), ("--row", EXTREME_INTS), ("--shard", ["0/0", "1/1", "-1/2", "4294967297/2", "a/b", "1"]), ("--video-camera", EXTREME_INTS)):
        for v in vals:
            fit("%s %s" % (flag, v), **{flag: v})
    for k, p in c.texts.items():
        fit("--config " + k, **{"--config": str(p)})
        fit("--parts " + k, **{"--parts": str(p)})
        fit("--cameras " + k, **{"--cameras": str(p)})
        out.append(("fit", "--resume " + k, ["fit", "--resume", str(p)]))
    for k, p in c.plys.items():
        fit("--particles " + k, **{"--particles": str(p)})
        fit("--scene " + k, **{"--scene": str(p)})
    for k, p in c.configs.items():
        fit("--sim " + k, **{"--sim": str(p)})
    # FIT.toml bounds beyond what the simulator accepts, and a table written as an array.
    tiny = 'iters = 1\nprecision = "f32"\nframes = 3\n[init]\ncandidates = 2\nframes = 2\n'
    for i, extra in enumerate(['[[parts]]\nid = 0\nbounds = { E = [1e3, 1e300] }\n',
                               '[[parts]]\nid = 0\nbounds = { density = [1e-300, 1e3] }\n',
                               '[[parts]]\nid = 0\nbounds = { nu = [0.1, 0.7] }\n',
                               'parts = [[0, ["E"]]]\n']):
        fit("--config bounds_%d" % i, **{"--config": str(c.file("fit_bounds_%d.toml" % i, tiny + extra))})
    # bench-scale: sizes at and past their limits.
    for flag in ("--cells", "--gaussians", "--frames", "--substeps", "--resolution", "--band-rows"):
        for v in EXTREME_INTS:
            out.append(("bench-scale", "%s %s" % (flag, v), ["bench-scale", flag, v, "--json", o("bench.json")]))
    for v in EXTREME_INTS + ["10001"]:
        out.append(("bench-scale", "--init " + v, ["bench-scale", "--init", v]))
    for k, p in c.texts.items():
        out.append(("bench-scale", "--reference " + k, ["bench-scale", "--reference", str(p), "--cells", "0"]))
    # dataset inspect, eval, ablate, merge: hostile folders.
    for k, p in list(c.texts.items()) + list(c.ply_dirs.items())[:3]:
        out.append(("dataset", "inspect " + k, ["dataset", "inspect", str(p)]))
        out.append(("eval", k, ["eval", str(p)]))
        out.append(("ablate", "--dataset " + k, ["ablate", "--dataset", str(p), "--study", "main", "--out", o("abl")]))
        out.append(("merge", k, ["merge", str(p)]))
    dsd = fx / "datasets" / "physdreamer" / "toyplant"
    for v in ("0/0", "3/2", "-1/2", "4294967297/4294967297", "x"):
        out.append(("ablate", "--shard " + v, ["ablate", "--dataset", str(dsd), "--study", "main", "--out", o("ablsh"), "--shard", v]))
    for v in ("bogus", "", "main,main"):
        out.append(("ablate", "--study " + v, ["ablate", "--dataset", str(dsd), "--out", o("ablst"), "--study", v]))
    for v in EXTREME_FLOATS + ["1e9"]:
        out.append(("eval", "--fps " + v, ["eval", str(c.texts["dir"]), "--fps", v]))
    # demo: options past their limits (a valid one would run the whole demo).
    for flag in ("--iters", "--candidates", "--seed"):
        for v in ("4294967297", "18446744073709551617", "-1", "abc"):
            out.append(("demo", "%s %s" % (flag, v), ["demo", "--quick", "--small", "--out", o("demo"), flag, v]))
    for k in ("garbage", "empty", "dir", "missing"):
        out.append(("demo", "--scene " + k, ["demo", "--scene", str(c.texts[k]), "--out", o("demos")]))
    return out


def classify(rc, stderr, timed_out):
    if timed_out:
        return "timeout"
    if "panicked" in stderr or rc == 101 or rc < 0:
        return "panic"
    if rc == 0:
        return "ok"
    if not stderr.strip():
        return "silent"
    return "typed"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default="target/release/r4d", help="the r4d binary")
    ap.add_argument("--work", default="/tmp/r4d-hostile-sweep", help="scratch folder (emptied)")
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds per run")
    ap.add_argument("--only", default=None, help="only this subcommand")
    args = ap.parse_args()
    # The runs start in the scratch folder: a relative binary path is resolved here first.
    args.bin = str(Path(args.bin).resolve())
    if not os.access(args.bin, os.X_OK):
        sys.exit("--bin %s: not an executable (build it with cargo build --release)" % args.bin)
    repo = Path(__file__).resolve().parent.parent
    work = Path(args.work).resolve()
    shutil.rmtree(work, ignore_errors=True)
    (work / "out").mkdir(parents=True)
    corpus = Corpus(work / "corpus")
    corpus.build(repo)
    # Setup: the demo's inputs, the base of the fit runs (a quick, small demo).
    if args.only in (None, "fit"):
        print("setup: r4d demo --quick --small (the fit runs' base inputs) ...", flush=True)
        subprocess.run([args.bin, "demo", "--quick", "--small", "--out", str(work / "demo")],
                       capture_output=True, timeout=900, cwd=str(work))
    all_runs = [r for r in runs(corpus, repo, work) if args.only in (None, r[0])]
    results = []
    t_start = time.time()
    env = dict(os.environ, RUST_BACKTRACE="0")
    for i, (cmd, label, argv) in enumerate(all_runs):
        t0 = time.time()
        try:
            p = subprocess.run([args.bin] + argv, capture_output=True, timeout=args.timeout, env=env, cwd=str(work))
            rc, err, timed_out = p.returncode, p.stderr.decode("utf8", "replace"), False
        except subprocess.TimeoutExpired as e:
            rc, err, timed_out = None, (e.stderr or b"").decode("utf8", "replace"), True
        cls = classify(rc if rc is not None else 0, err, timed_out)
        last = [ln[:300] for ln in err.strip().splitlines() if ln.strip()]
        results.append({
            "command": cmd, "label": label, "argv": argv, "class": cls, "exit": rc,
            "seconds": round(time.time() - t0, 2), "stderr_tail": last[-3:] if last else [],
        })
        print("%4d/%d %-8s %-18s %-40s %s" % (i + 1, len(all_runs), cls, cmd, label[:40], (last[-1][:100] if last else "")), flush=True)
    counts = {}
    per_cmd = {}
    for r in results:
        counts[r["class"]] = counts.get(r["class"], 0) + 1
        per_cmd.setdefault(r["command"], {}).setdefault(r["class"], 0)
        per_cmd[r["command"]][r["class"]] += 1
    report = {"runs": len(results), "counts": counts, "per_command": per_cmd, "timeout_s": args.timeout,
              "wall_s": round(time.time() - t_start, 1), "results": results}
    (work / "report.json").write_text(json.dumps(report, indent=1))
    print("\n%d runs in %.0f s: %s" % (len(results), time.time() - t_start, json.dumps(counts)))
    for cmd, cl in sorted(per_cmd.items()):
        print("  %-20s %s" % (cmd, json.dumps(cl)))
    bad = [r for r in results if r["class"] in ("panic", "silent", "timeout")]
    for r in bad:
        print("%s: r4d %s\n    %s" % (r["class"], " ".join(r["argv"]), " | ".join(r["stderr_tail"])))
    print("report: %s" % (work / "report.json"))
    return 1 if any(r["class"] in ("panic", "silent") for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
