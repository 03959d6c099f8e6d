"""The airground ErfNet weights format (docs/segmentation.md), written and read from Python.

Little-endian throughout:
  magic "AGERFNET" | u32 version (1) | u32 num_classes | u32 input_width | u32 input_height |
  f32 mean[3] | f32 std[3] | u32 class_names_bytes | class names (UTF-8, comma separated) |
  u32 tensor_count | tensor_count x { u16 name_bytes | name | u8 dtype (1 f32, 2 f16) | u8 ndim |
  u32 dims[ndim] | data } | u32 CRC-32 (zlib/IEEE) of every byte before it.
"""
import struct
import zlib

import numpy as np

MAGIC = b"AGERFNET"
VERSION = 1
DTYPE_F32 = 1
DTYPE_F16 = 2


def write(path, tensors, num_classes, input_width, input_height, mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0),
          class_names=(), fp16=False):
    """tensors: ordered {name: numpy array}. Writes the file and returns its size in bytes."""
    names = ",".join(class_names).encode("utf-8")
    out = bytearray()
    out += MAGIC
    out += struct.pack("<IIII", VERSION, num_classes, input_width, input_height)
    out += struct.pack("<3f", *mean) + struct.pack("<3f", *std)
    out += struct.pack("<I", len(names)) + names
    out += struct.pack("<I", len(tensors))
    for name, arr in tensors.items():
        a = np.ascontiguousarray(arr, dtype=np.float16 if fp16 else np.float32)
        nb = name.encode("utf-8")
        out += struct.pack("<H", len(nb)) + nb
        out += struct.pack("<BB", DTYPE_F16 if fp16 else DTYPE_F32, a.ndim)
        out += struct.pack(f"<{a.ndim}I", *a.shape)
        out += a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes()
    out += struct.pack("<I", zlib.crc32(bytes(out)) & 0xFFFFFFFF)
    with open(path, "wb") as f:
        f.write(out)
    return len(out)


def read(path):
    """Returns (header dict, {name: float32 array}); raises ValueError naming what is wrong."""
    data = open(path, "rb").read()
    if len(data) < 8 + 4 or data[:8] != MAGIC:
        raise ValueError(f"{path}: not an airground ErfNet weights file (bad magic)")
    crc = struct.unpack_from("<I", data, len(data) - 4)[0]
    if zlib.crc32(data[:-4]) & 0xFFFFFFFF != crc:
        raise ValueError(f"{path}: checksum mismatch")
    off = 8
    version, classes, w, h = struct.unpack_from("<IIII", data, off)
    off += 16
    mean = struct.unpack_from("<3f", data, off)
    std = struct.unpack_from("<3f", data, off + 12)
    off += 24
    (nlen,) = struct.unpack_from("<I", data, off)
    off += 4
    names = data[off:off + nlen].decode("utf-8")
    off += nlen
    (count,) = struct.unpack_from("<I", data, off)
    off += 4
    tensors = {}
    for _ in range(count):
        (l,) = struct.unpack_from("<H", data, off)
        off += 2
        name = data[off:off + l].decode("utf-8")
        off += l
        dtype, ndim = struct.unpack_from("<BB", data, off)
        off += 2
        dims = struct.unpack_from(f"<{ndim}I", data, off)
        off += 4 * ndim
        dt = np.dtype("<f2") if dtype == DTYPE_F16 else np.dtype("<f4")
        n = int(np.prod(dims)) if ndim else 1
        tensors[name] = np.frombuffer(data, dtype=dt, count=n, offset=off).reshape(dims).astype(np.float32)
        off += n * dt.itemsize
    header = dict(version=version, num_classes=classes, input_width=w, input_height=h, mean=mean, std=std,
                  class_names=[s for s in names.split(",") if s])
    return header, tensors
