#!/usr/bin/env python3
"""Read a cellflip checkpoint (step-NNNNNNNN.ckpt) with numpy alone.

    python3 tools/checkpoint.py recordings/dam-2d.checkpoints/step-00000120.ckpt

prints the metadata and every array's name, dtype and shape. From Python:

    from checkpoint import load
    meta, arrays = load("step-00000120.ckpt")
    pos = arrays["particles.pos"]        # (n, dim) float64, grid units (cells)

and writes edited arrays back, with the checksum recomputed (same names, dtypes and shapes):

    from checkpoint import store
    store("step-00000120.ckpt", {"particles.pos": pos * 0.5}, into="edited.ckpt")

cellflip checks what a checkpoint holds before it resumes from one (finite positions inside
the domain, counts that add up, ...): an edit that makes no state is refused, naming the
array and its first bad element.

The format is docs/checkpoints.md's: magic, version, a TOML header, aligned arrays, CRC-32.
"""
import sys
import tomllib
import zlib

import numpy as np

MAGIC = b"\x89CFCKPT\n"
END = b"CFCKEND\n"
VERSION = 2


def load(path):
    """The checkpoint's metadata (a dict of strings) and arrays (a dict of numpy arrays)."""
    data = open(path, "rb").read()
    if data[:8] != MAGIC:
        raise ValueError(f"{path}: not a cellflip checkpoint")
    if data[-8:] != END:
        raise ValueError(f"{path}: truncated (no end mark)")
    version, header_len = np.frombuffer(data, "<u4", 2, 8)
    if version != VERSION:
        raise ValueError(f"{path}: format version {version}, this reader knows {VERSION}")
    body = len(data) - 12
    stored = int(np.frombuffer(data, "<u4", 1, body)[0])
    if zlib.crc32(data[:body]) != stored:
        raise ValueError(f"{path}: corrupted (checksum)")
    header = tomllib.loads(data[16 : 16 + header_len].decode())
    arrays = {}
    for a in header.get("array", []):
        shape = tuple(a["shape"])
        count = int(np.prod(shape, dtype=np.int64))
        arrays[a["name"]] = np.frombuffer(data, a["dtype"], count, a["offset"]).reshape(shape)
    return header["meta"], arrays


def store(path, edits, into=None):
    """Writes the checkpoint at `path` with the arrays of `edits` (name -> array of the dtype
    and shape it has there) in place of its own, to `into` (default: `path` itself), with the
    checksum recomputed."""
    data = bytearray(open(path, "rb").read())
    load(path)  # checks magic, version and checksum first
    header_len = int(np.frombuffer(data, "<u4", 1, 12)[0])
    header = tomllib.loads(data[16 : 16 + header_len].decode())
    where = {a["name"]: a for a in header.get("array", [])}
    for name, values in edits.items():
        if name not in where:
            raise KeyError(f"{path}: no array '{name}'")
        a = where[name]
        values = np.asarray(values)
        if values.dtype != np.dtype(a["dtype"]) or values.shape != tuple(a["shape"]):
            raise ValueError(
                f"{path}: '{name}' is {a['dtype']} {tuple(a['shape'])}, "
                f"the edit {values.dtype.str} {values.shape}"
            )
        data[a["offset"] : a["offset"] + values.nbytes] = values.tobytes()
    body = len(data) - 12
    data[body : body + 4] = np.uint32(zlib.crc32(data[:body])).tobytes()
    open(into or path, "wb").write(data)


if __name__ == "__main__":
    meta, arrays = load(sys.argv[1])
    for k, v in meta.items():
        if k != "scene.toml":
            print(f"{k} = {v}")
    for name, a in arrays.items():
        print(f"{name:24} {a.dtype.str:4} {a.shape}")
