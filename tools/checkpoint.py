#!/usr/bin/env python3
"""Read a cellflip checkpoint (step-NNNNNNNN.ckpt) with numpy alone.

    python3 tools/checkpoint.py recordings/dam-2d.checkpoints/step-00000120.ckpt

prints the metadata and every array's name, dtype and shape. From Python:

    from checkpoint import load
    meta, arrays = load("step-00000120.ckpt")
    pos = arrays["particles.pos"]        # (n, dim) float64, grid units (cells)

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


if __name__ == "__main__":
    meta, arrays = load(sys.argv[1])
    for k, v in meta.items():
        if k != "scene.toml":
            print(f"{k} = {v}")
    for name, a in arrays.items():
        print(f"{name:24} {a.dtype.str:4} {a.shape}")
